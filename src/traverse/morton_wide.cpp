#include "traverse/morton_wide.h"

#include <algorithm>
#include <bit>
#include <cmath>
#include <vector>

#include "bvh/morton.h"
#include "core/check.h"
#include "core/parallel.h"
#include "core/raw_array.h"
#include "core/vec.h"
#include "geometry/prim_ref.h"
#include "kestrel/error.h"
#include "traverse/wide_bvh.h"

namespace kestrel {

namespace {

// Ranges of at most this many triangles are built as one task, in parallel with the others.
constexpr uint32_t task_size = 4096;
constexpr uint32_t leaf_size = 4;              // one TriangleBlock
constexpr uint32_t top_pending = 0x7FFFFFFFu;  // a top node's slot whose task is not yet built

Bounds3 empty_box() {
  return {{INFINITY, INFINITY, INFINITY}, {-INFINITY, -INFINITY, -INFINITY}};
}

// Splits [b, e) into at most W parts: a part above the leaf size is split again (the one of
// the largest Morton cell, then of most references) until there are W parts or every part
// is a leaf. Returns the part count.
template <int W, class Key>
int partition_node(const Key* keys, uint32_t b, uint32_t e, uint32_t* lo, uint32_t* hi) {
  int parts = 1;
  lo[0] = b, hi[0] = e;
  while (parts < W) {
    int big = -1;
    uint64_t best = 0;
    for (int i = 0; i < parts; ++i) {
      const uint32_t size = hi[i] - lo[i];
      if (size <= leaf_size) continue;
      // The part of the largest Morton cell (fewest common leading key bits), then of most
      // references: the cell stands in for the part's box, which is not known yet.
      const Key x = keys[lo[i]] ^ keys[hi[i] - 1];
      const uint64_t prefix = x ? uint64_t(std::countl_zero(x)) : uint64_t(sizeof(Key) * 8);
      const uint64_t rank = (uint64_t(127 - prefix) << 32) | size;
      if (rank > best) big = i, best = rank;
    }
    if (big < 0) break;
    const uint32_t m = morton_split(keys, lo[big], hi[big]);
    lo[parts] = m, hi[parts] = hi[big];
    hi[big] = m;
    ++parts;
  }
  return parts;
}

// Nodes and blocks a subtree over [b, e) (e - b > leaf_size) takes, so every task knows
// where its part of the arrays starts. Its splits are recorded in `plan` (per node, depth
// first: the part count, then each part's first and end), which the build replays instead of
// searching the keys again.
template <int W, class Key>
void count_subtree(const Key* keys, uint32_t b, uint32_t e, size_t& nodes, size_t& blocks,
                   std::vector<uint32_t>& plan) {
  uint32_t lo[W], hi[W];
  const int parts = partition_node<W>(keys, b, e, lo, hi);
  ++nodes;
  plan.push_back(uint32_t(parts));
  for (int j = 0; j < parts; ++j) plan.push_back(lo[j]), plan.push_back(hi[j]);
  for (int j = 0; j < parts; ++j) {
    if (hi[j] - lo[j] <= leaf_size)
      ++blocks;
    else
      count_subtree<W>(keys, lo[j], hi[j], nodes, blocks, plan);
  }
}

// The blocks read their triangles from the meshes in key order (TrianglesById, prefetched)
// instead of from a gathered copy written first and read back.

// One block over sorted positions [b, e) (1 to 4 triangles; unused lanes repeat the last);
// returns its box.
Bounds3 write_leaf(const TrianglesById& tris, const uint32_t* ids, uint32_t b, uint32_t e,
                   TriangleBlock& blk) {
  Vec3 lo{INFINITY, INFINITY, INFINITY}, hi{-INFINITY, -INFINITY, -INFINITY};
  for (uint32_t lane = 0; lane < 4; ++lane) {
    const uint32_t k = std::min(b + lane, e - 1);
    const Triangle t = tris.at(k);
    write_block_lane(blk, int(lane), t, ids[k]);
    lo = min(lo, min(t.v0, min(t.v1, t.v2)));
    hi = max(hi, max(t.v0, max(t.v1, t.v2)));
  }
  blk.prim_id[0] |= block_last_bit;
  return {lo, hi};
}

// Builds a task's subtree by replaying count_subtree's record of its splits, writing nodes
// and blocks at consecutive indices from next_node / next_block (the arrays are sized in
// advance).
template <int W, class Node>
struct Builder {
  const TrianglesById& tris;  // in key order
  const uint32_t* ids;        // prim ids in key order
  Node* nodes;
  TriangleBlock* blocks;
  uint32_t next_node, next_block;
  const uint32_t* plan;  // count_subtree's record, read in order

  // Fills node `index` (the plan's next node) and returns its box.
  Bounds3 build(uint32_t index) {
    uint32_t lo[W], hi[W];
    const int parts = int(*plan++);
    for (int j = 0; j < parts; ++j) lo[j] = *plan++, hi[j] = *plan++;
    Node node;
    Bounds3 total = empty_box();
    for (int j = 0; j < W; ++j) {
      if (j >= parts) {
        set_wide_slot(node, j, empty_box(), wide_empty);
        continue;
      }
      Bounds3 box;
      uint32_t ref;
      if (hi[j] - lo[j] <= leaf_size) {
        ref = wide_leaf_bit | next_block;
        box = write_leaf(tris, ids, lo[j], hi[j], blocks[next_block++]);
      } else {
        ref = next_node++;
        box = build(ref);
      }
      set_wide_slot(node, j, box, ref);
      extend(total, box);
    }
    nodes[index] = node;
    return total;
  }
};

// The top of the tree, serially: nodes until ranges fit a task, into growing arrays (the
// top is small); a task's slot is left pending (its box and index come once it is built).
template <int W, class Node, class Key>
struct Top {
  const Key* keys;
  const TrianglesById& tris;
  const uint32_t* ids;
  std::vector<Node> nodes;
  std::vector<TriangleBlock> blocks;
  struct Task {
    uint32_t node, slot, b, e;
  };
  std::vector<Task> tasks;

  void build(uint32_t index, uint32_t b, uint32_t e) {
    uint32_t lo[W], hi[W];
    const int parts = partition_node<W>(keys, b, e, lo, hi);
    Node node;
    std::vector<std::pair<int, uint32_t>> inner;  // (slot, node) of top children
    for (int j = 0; j < W; ++j) {
      if (j >= parts) {
        set_wide_slot(node, j, empty_box(), wide_empty);
        continue;
      }
      const uint32_t n = hi[j] - lo[j];
      if (n <= leaf_size) {
        const uint32_t ref = wide_leaf_bit | uint32_t(blocks.size());
        set_wide_slot(node, j, write_leaf(tris, ids, lo[j], hi[j], blocks.emplace_back()), ref);
      } else if (n <= task_size) {
        tasks.push_back({index, uint32_t(j), lo[j], hi[j]});
        set_wide_slot(node, j, empty_box(), top_pending);
      } else {
        const uint32_t child = uint32_t(nodes.size());
        nodes.emplace_back();
        set_wide_slot(node, j, empty_box(), child);
        inner.push_back({j, child});
      }
    }
    nodes[index] = node;
    for (const auto& [slot, child] : inner) build(child, lo[slot], hi[slot]);
  }
};

template <class Node>
Bounds3 node_box(const Node& node, int width) {
  Bounds3 box = empty_box();
  for (int j = 0; j < width; ++j)
    if (node.child[j] != wide_empty)
      extend(box, Bounds3{{node.bounds[0][j], node.bounds[2][j], node.bounds[4][j]},
                          {node.bounds[1][j], node.bounds[3][j], node.bounds[5][j]}});
  return box;
}

template <int W, class Node, class Wide, class Key>
Wide build_wide(const Scene& scene, std::span<const PrimRef> refs, const Bounds3* centroids) {
  Wide out;
  const size_t n = refs.size();
  if (n == 0) return out;
  if (n >= size_t(block_last_bit))
    throw Error(ErrorCode::invalid_argument, "wide BVH: more than 2^31 primitives");
  // The prim ids ride along the sort as its values (the refs are in id order, so ties keep
  // id order): no gather through the refs afterwards.
  RawArray<Key> keys;
  RawArray<uint32_t> ids;
  morton_sort(refs, MortonValue::prim_id, keys, ids, centroids);
  const TrianglesById tris(scene, {ids.data(), n});

  // The top, serially; then the tasks, in parallel: counted, placed after the top in task
  // order, and built in place.
  Top<W, Node, Key> top{keys.data(), tris, ids.data(), {Node{}}, {}, {}};
  if (n <= leaf_size) {  // the root (always an inner node) with one leaf
    set_wide_slot(top.nodes[0], 0,
                  write_leaf(tris, ids.data(), 0, uint32_t(n), top.blocks.emplace_back()),
                  wide_leaf_bit);
    for (int j = 1; j < W; ++j) set_wide_slot(top.nodes[0], j, empty_box(), wide_empty);
  } else {
    top.build(0, 0, uint32_t(n));
  }
  const size_t tasks = top.tasks.size();
  std::vector<size_t> node_at(tasks + 1, top.nodes.size()), block_at(tasks + 1, top.blocks.size());
  std::vector<std::vector<uint32_t>> plans(tasks);
  parallel_for(0, tasks, 1, [&](size_t t0, size_t t1) {
    for (size_t t = t0; t < t1; ++t) {  // counts first, made offsets below
      plans[t].reserve((top.tasks[t].e - top.tasks[t].b) / 2);
      count_subtree<W>(keys.data(), top.tasks[t].b, top.tasks[t].e, node_at[t + 1], block_at[t + 1],
                       plans[t]);
    }
  });
  for (size_t t = 0; t < tasks; ++t) {
    node_at[t + 1] = node_at[t] + (node_at[t + 1] - top.nodes.size());
    block_at[t + 1] = block_at[t] + (block_at[t + 1] - top.blocks.size());
  }
  if (block_at[tasks] >= size_t(wide_leaf_bit) || node_at[tasks] >= size_t(wide_leaf_bit))
    throw Error(ErrorCode::invalid_argument, "wide BVH: too many nodes or triangle blocks");
  out.nodes.resize(node_at[tasks]);
  out.blocks.resize(block_at[tasks]);
  std::copy(top.nodes.begin(), top.nodes.end(), out.nodes.begin());
  std::copy(top.blocks.begin(), top.blocks.end(), out.blocks.begin());
  parallel_for(0, tasks, 1, [&](size_t t0, size_t t1) {
    for (size_t t = t0; t < t1; ++t) {
      const auto& task = top.tasks[t];
      const uint32_t root = uint32_t(node_at[t]);
      Builder<W, Node> b{tris,
                         ids.data(),
                         out.nodes.data(),
                         out.blocks.data(),
                         root + 1,
                         uint32_t(block_at[t]),
                         plans[t].data()};
      const Bounds3 box = b.build(root);
      KESTREL_CHECK(b.next_node == node_at[t + 1] && b.next_block == block_at[t + 1] &&
                        b.plan == plans[t].data() + plans[t].size(),
                    "morton wide build: a task wrote other counts than it counted");
      // Tasks of one parent fill different slots of it: different floats, no race.
      set_wide_slot(out.nodes[task.node], int(task.slot), box, root);
    }
  });
  // The top's boxes, bottom-up: its children follow their parents in the array.
  const uint32_t top_nodes = uint32_t(top.nodes.size());
  for (uint32_t i = top_nodes; i-- > 0;) {
    Node& node = out.nodes[i];
    for (int j = 0; j < W; ++j) {
      const uint32_t ref = node.child[j];
      if (ref < top_nodes) set_wide_slot(node, j, node_box(out.nodes[ref], W), ref);
    }
  }
  return out;
}

}  // namespace

Bvh4 build_morton_bvh4(const Scene& scene, std::span<const PrimRef> refs, const BuildConfig& config,
                       const Bounds3* centroids) {
  return config.morton_bits == 63 ? build_wide<4, Bvh4Node, Bvh4, uint64_t>(scene, refs, centroids)
                                  : build_wide<4, Bvh4Node, Bvh4, uint32_t>(scene, refs, centroids);
}

Bvh8 build_morton_bvh8(const Scene& scene, std::span<const PrimRef> refs, const BuildConfig& config,
                       const Bounds3* centroids) {
  return config.morton_bits == 63 ? build_wide<8, Bvh8Node, Bvh8, uint64_t>(scene, refs, centroids)
                                  : build_wide<8, Bvh8Node, Bvh8, uint32_t>(scene, refs, centroids);
}

}  // namespace kestrel
