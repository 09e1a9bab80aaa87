#include "traverse/wide_bvh.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <vector>

#include <fmt/format.h>

#include "core/check.h"
#include "core/parallel.h"
#include "core/simd/vec4f.h"
#include "geometry/prim_ref.h"
#include "kestrel/error.h"

namespace kestrel {

namespace {

float half_area(const Bvh2Node& n) {
  const float dx = n.hi.x - n.lo.x, dy = n.hi.y - n.lo.y, dz = n.hi.z - n.lo.z;
  return dx * dy + dy * dz + dz * dx;
}

// Which binary nodes become the slots of each wide node: the SAH-optimal choice for the given
// binary tree (the dynamic program of Ylitie et al. 2017, section 3.1), with the flat subtrees
// (below) fixed as leaves. cost(n, i), i = 1..W: the least SAH cost of subtree n held in at
// most i slots of one wide node, a wide node's visit costing its area and a leaf its area per
// block (what wide_sah_cost measures). One slot: n itself, a leaf (flat) or a wide node of its
// own, A(n) + dist(n, W); i slots: cost(n, i - 1), or n's two children sharing them, dist(n, i)
// = min over k of cost(l, k) + cost(r, i - k). (Opening the largest-area child instead, until
// the node was full: wide SAH 22.80 against 21.46 inside Sponza; docs/bvh_layout.md.)
template <int W>
using SlotCosts = std::array<float, W>;  // [i - 1]: cost(n, i)

// dist(n, i) for i = 1..W in [i - 1] (infinite for one slot), from the children's costs: for
// each k, the left child's cost(l, k) plus the right's cost(r, i - k) read from a padded copy
// at offset -k, so every k is one pass over the lanes (vectorised).
template <int W>
void child_splits(const SlotCosts<W>& cl, const SlotCosts<W>& cr, float (&dist)[W]) {
  constexpr float inf = std::numeric_limits<float>::infinity();
  float padded[2 * W];
  for (int j = 0; j < W; ++j) padded[j] = inf, padded[W + j] = cr[j];
  for (int j = 0; j < W; ++j) dist[j] = inf;
  for (int k = 1; k < W; ++k) {
    const float left = cl[k - 1];
    const float* right = padded + W - k;  // right[j] = cr[j - k], infinite for j < k
    for (int j = 0; j < W; ++j) dist[j] = std::min(dist[j], left + right[j]);
  }
}

// The k of dist(n, i) = cost(l, k) + cost(r, i - k) that child_splits' minimum took (the
// first smallest: the same float sums).
template <int W>
int best_split(const SlotCosts<W>& cl, const SlotCosts<W>& cr, int i) {
  int best = 1;
  for (int k = 2; k < i; ++k)
    if (cl[k - 1] + cr[i - k - 1] < cl[best - 1] + cr[i - best - 1]) best = k;
  return best;
}

// cost(n, i) for i = 1..W of an inner node n (not flat) from its children's.
template <int W>
void inner_slot_costs(SlotCosts<W>& c, float area, const SlotCosts<W>& cl, const SlotCosts<W>& cr) {
  float dist[W];
  child_splits<W>(cl, cr, dist);
  c[0] = area + dist[W - 1];
  for (int i = 1; i < W; ++i) c[i] = std::min(c[i - 1], dist[i]);
}

// Which binary subtrees become one wide leaf. A SIMD leaf test costs about the same for one
// triangle as for four, so leaf cost counts blocks of four: C(leaf) = A * ceil(n / 4) and
// C(inner) = A + C(left) + C(right) (one SIMD box test, then the children). A subtree of at
// most max_leaf primitives is flattened when that is no more expensive; a subtree of at most
// four always is. This turns the binary builders' many 2-triangle leaves into full blocks.
template <int W>
struct LeafPlan {
  Buffer<uint32_t> count;   // primitives under each Bvh2 node
  Buffer<uint8_t> flat;     // 1: emit the whole subtree as one leaf
  Buffer<uint32_t> blocks;  // blocks the subtree's leaves take (flat: one leaf's)
  // The subtree's first leaf-order primitive when its leaves, left first, cover one run
  // [first, first + count) (top-down builders' trees), else scattered: then they are walked.
  Buffer<uint32_t> first;
  Buffer<SlotCosts<W>> slots;  // cost(n, i) of the wide nodes' slots
  size_t block_count = 0;      // triangle blocks of all leaves (flat subtrees, parent not flat)
  static constexpr uint32_t scattered = ~0u;
};

// Nodes in an order that puts every child after its parent: the node array itself when its
// builder allocated children after their parent (all of kestrel's do; one linear check),
// else breadth first.
Buffer<uint32_t> parents_first(const Bvh2& bvh) {
  const size_t n = bvh.nodes.size();
  bool sorted = true;
  for (size_t i = 0; i < n && sorted; ++i)
    sorted = bvh.nodes[i].is_leaf() || bvh.nodes[i].index > i;
  if (sorted) return {};  // empty: use the array order
  Buffer<uint32_t> order{0};
  order.reserve(n);
  for (size_t i = 0; i < order.size(); ++i) {
    const Bvh2Node& node = bvh.nodes[order[i]];
    if (!node.is_leaf()) {
      order.push_back(node.index);
      order.push_back(node.index + 1);
    }
  }
  return order;
}

// Calls fn(id) for every node, children before their parents: parents_first backwards (the
// array backwards, not a breadth-first list, took the leaf plan from ~12 % of an LBVH's
// ready-to-trace build to ~3 %).
template <class Fn>
void for_each_child_first(const Bvh2& bvh, Fn&& fn) {
  const Buffer<uint32_t> order = parents_first(bvh);
  for (size_t i = order.empty() ? bvh.nodes.size() : order.size(); i-- > 0;)
    fn(order.empty() ? uint32_t(i) : order[i]);
}

template <int W>
LeafPlan<W> plan_leaves(const Bvh2& bvh, uint32_t max_leaf) {
  const size_t n = bvh.nodes.size();
  // Every entry is written below (children before parents) before it is read.
  LeafPlan<W> plan{Buffer<uint32_t>(n), Buffer<uint8_t>(n), Buffer<uint32_t>(n),
                   Buffer<uint32_t>(n), Buffer<SlotCosts<W>>(n)};
  const auto slots = [&](uint32_t id) -> SlotCosts<W>& { return plan.slots[id]; };
  Buffer<float> cost(n);
  Buffer<uint32_t>& blocks = plan.blocks;
  for_each_child_first(bvh, [&](uint32_t id) {
    const Bvh2Node& node = bvh.nodes[id];
    const float area = half_area(node);
    if (node.is_leaf()) {
      plan.count[id] = node.count;
      plan.first[id] = node.index;
      plan.flat[id] = 1;
      cost[id] = area * float((node.count + 3) / 4);
      blocks[id] = (node.count + 3) / 4;
      slots(id).fill(cost[id]);
      return;
    }
    const uint32_t l = node.index, r = node.index + 1;
    const uint32_t c = plan.count[l] + plan.count[r];
    plan.count[id] = c;
    const uint32_t fl = plan.first[l];
    plan.first[id] = fl != LeafPlan<W>::scattered && plan.first[r] == fl + plan.count[l]
                         ? fl
                         : LeafPlan<W>::scattered;
    const float split = area + cost[l] + cost[r];
    const float leaf = area * float((c + 3) / 4);
    if (c <= max_leaf && (c <= 4 || leaf <= split)) {
      plan.flat[id] = 1;
      cost[id] = leaf;
      blocks[id] = (c + 3) / 4;
      slots(id).fill(leaf);
    } else {
      plan.flat[id] = 0;
      cost[id] = split;
      blocks[id] = blocks[l] + blocks[r];
      inner_slot_costs<W>(slots(id), area, slots(l), slots(r));
    }
  });
  plan.block_count = n > 0 ? blocks[0] : 0;
  return plan;
}

// Wide nodes from a binary tree: flat[i] marks the binary subtrees that become one leaf
// slot, cost holds cost(n, i) of every binary node (plan_leaves); emit_leaf(i) returns a leaf
// slot's child reference.
template <int W, class Node, class EmitLeaf>
void build_wide_nodes(const Bvh2& bvh, std::span<const uint8_t> flat,
                      std::span<const SlotCosts<W>> cost, Buffer<Node>& nodes,
                      EmitLeaf&& emit_leaf) {
  struct Work {
    uint32_t src, dst;
  };
  std::vector<Work> todo{{0, 0}};
  nodes.emplace_back();
  while (!todo.empty()) {
    const Work work = todo.back();
    todo.pop_back();
    uint32_t kids[W];
    float area[W];
    int n = 0;
    if (flat[work.src]) {
      kids[n++] = work.src;  // a one-leaf tree: the root holds one leaf slot
    } else {
      // The slots the plan gives the node's subtree: (binary node, slots) pairs expanded
      // until each holds one slot.
      struct Part {
        uint32_t node;
        int slots;
      };
      Part parts[2 * W];
      int np = 0;
      const auto split = [&](uint32_t at, int slots) {
        const uint32_t l = bvh.nodes[at].index;
        const int k = best_split<W>(cost[l], cost[l + 1], slots);
        parts[np++] = {l + 1, slots - k};
        parts[np++] = {l, k};
      };
      split(work.src, W);
      while (np > 0) {
        Part p = parts[--np];
        // cost(n, i) = cost(n, i - 1): fewer slots were as good (inner_slot_costs).
        while (p.slots > 1 && !flat[p.node] &&
               cost[p.node][p.slots - 1] == cost[p.node][p.slots - 2])
          --p.slots;
        if (p.slots == 1 || flat[p.node])
          kids[n++] = p.node;
        else
          split(p.node, p.slots);
      }
    }
    // Slots by surface area, largest first: occlusion rays visit them in slot order, and a
    // ray is likelier to hit a larger box (any hit on the diffuse rays: Sponza +36 %, bunny
    // grid +17 %, Lamborghini +4 %; closest hit sorts by distance and is unchanged).
    for (int i = 0; i < n; ++i) area[i] = half_area(bvh.nodes[kids[i]]);
    int slot[W];  // an insertion sort, stable (std::stable_sort took a heap buffer per node)
    for (int i = 0; i < n; ++i) {
      int k = i;
      for (; k > 0 && area[slot[k - 1]] < area[i]; --k) slot[k] = slot[k - 1];
      slot[k] = i;
    }
    uint32_t sorted[W];
    for (int i = 0; i < n; ++i) sorted[i] = kids[slot[i]];
    std::copy(sorted, sorted + n, kids);
    Node node;
    const size_t first_new = todo.size();
    for (int j = 0; j < W; ++j) {
      if (j >= n) {
        const float inf = INFINITY;
        set_wide_slot(node, j, Bounds3{{inf, inf, inf}, {-inf, -inf, -inf}}, wide_empty);
        continue;
      }
      const Bvh2Node& k = bvh.nodes[kids[j]];
      const Bounds3 box{k.lo, k.hi};
      if (flat[kids[j]]) {
        set_wide_slot(node, j, box, emit_leaf(kids[j]));
      } else {
        const uint32_t dst = uint32_t(nodes.size());
        nodes.emplace_back();
        todo.push_back({kids[j], dst});
        set_wide_slot(node, j, box, dst);
      }
    }
    std::reverse(todo.begin() + first_new, todo.end());  // first child is built next
    nodes[work.dst] = node;
  }
}

// Leaf-order triangles from a gathered array.
struct GatheredTriangles {
  std::span<const Triangle> tris;
  const Triangle& at(size_t k) const { return tris[k]; }
};

// Source: at(k) is the triangle of leaf-order index k (GatheredTriangles, or TrianglesById
// straight from the meshes, which prefetches for ascending k).
template <int W, class Node, class Wide, class Source>
Wide collapse(const Bvh2& bvh, const Source& tris, uint32_t max_leaf) {
  Wide out;
  if (bvh.empty()) return out;
  if (bvh.prim_ids.size() >= size_t(block_last_bit))
    throw Error(ErrorCode::invalid_argument, "wide BVH: more than 2^31 primitives");
  const LeafPlan<W> plan = plan_leaves<W>(bvh, std::max<uint32_t>(max_leaf, 4));
  const size_t block_count = plan.block_count;
  if (block_count >= size_t(wide_leaf_bit))
    throw Error(ErrorCode::invalid_argument, "wide BVH: too many triangle blocks");
  out.blocks.resize(block_count);
  out.nodes.reserve(bvh.nodes.size() / (W - 1) + 1);
  // Each leaf's blocks in leaf order (the binary tree's depth-first order, left first): the
  // block pass below then reads the triangles and writes the blocks front to back, in
  // parallel (disjoint runs of out.blocks: the same bytes for any thread count). The nodes,
  // built depth first by area, only look up their leaves' first blocks.
  struct LeafJob {
    uint32_t subtree, first_block;
  };
  Buffer<LeafJob> jobs;       // pooled when large: a rebuilt scene does not fault it in again
  jobs.reserve(block_count);  // a leaf takes at least one block
  Buffer<uint32_t> first_block(bvh.nodes.size());  // written for the flat subtrees' roots only
  {
    std::vector<LeafJob> stack{{0, 0}};
    while (!stack.empty()) {
      const LeafJob at = stack.back();
      stack.pop_back();
      if (plan.flat[at.subtree]) {
        first_block[at.subtree] = at.first_block;
        jobs.push_back(at);
        continue;
      }
      const uint32_t l = bvh.nodes[at.subtree].index;
      stack.push_back({l + 1, at.first_block + plan.blocks[l]});
      stack.push_back({l, at.first_block});
    }
  }
  build_wide_nodes<W>(bvh, plan.flat, plan.slots, out.nodes,
                      [&](uint32_t subtree) { return wide_leaf_bit | first_block[subtree]; });
  parallel_for(0, jobs.size(), 2048, [&](size_t jb, size_t je) {
    std::vector<uint32_t> prims, walk;  // leaf-order indices of a flat subtree
    for (size_t j = jb; j < je; ++j) {
      prims.clear();
      if (const uint32_t first = plan.first[jobs[j].subtree]; first != LeafPlan<W>::scattered) {
        for (uint32_t k = 0; k < plan.count[jobs[j].subtree]; ++k) prims.push_back(first + k);
      } else {
        walk.assign(1, jobs[j].subtree);
      }
      while (!walk.empty()) {
        const Bvh2Node& n = bvh.nodes[walk.back()];
        walk.pop_back();
        if (n.is_leaf()) {
          for (uint32_t k = 0; k < n.count; ++k) prims.push_back(n.index + k);
        } else {
          walk.push_back(n.index + 1);
          walk.push_back(n.index);
        }
      }
      // The plan placed this leaf's blocks; a walk that found other primitives (a malformed
      // tree) must not write past them.
      KESTREL_CHECK(prims.size() == plan.count[jobs[j].subtree],
                    "collapse: a leaf holds other primitives than its plan counted");
      const uint32_t count = uint32_t(prims.size());
      const uint32_t nb = (count + 3) / 4;
      for (uint32_t b = 0; b < nb; ++b) {
        TriangleBlock& blk = out.blocks[jobs[j].first_block + b];
        for (uint32_t lane = 0; lane < 4; ++lane) {
          const uint32_t k = prims[std::min(4 * b + lane, count - 1)];  // pad with the last one
          write_block_lane(blk, int(lane), tris.at(k), bvh.prim_ids[k]);
        }
        if (b + 1 == nb) blk.prim_id[0] |= block_last_bit;
      }
    }
  });
  KESTREL_CHECK(
      jobs.empty() ||
          jobs.back().first_block + (plan.count[jobs.back().subtree] + 3) / 4 == block_count,
      "collapse: the leaf plan counted other blocks");
  return out;
}

void grow(Bounds3& b, const Vec3& p) {
  b.lo = {std::min(b.lo.x, p.x), std::min(b.lo.y, p.y), std::min(b.lo.z, p.z)};
  b.hi = {std::max(b.hi.x, p.x), std::max(b.hi.y, p.y), std::max(b.hi.z, p.z)};
}

// Min / max over the four lanes of a 128-bit row.
float hmin(simd::Vec4f v) {
  v = min(v, simd::Vec4f(_mm_shuffle_ps(v.v, v.v, _MM_SHUFFLE(1, 0, 3, 2))));
  v = min(v, simd::Vec4f(_mm_shuffle_ps(v.v, v.v, _MM_SHUFFLE(2, 3, 0, 1))));
  return _mm_cvtss_f32(v.v);
}
float hmax(simd::Vec4f v) {
  v = max(v, simd::Vec4f(_mm_shuffle_ps(v.v, v.v, _MM_SHUFFLE(1, 0, 3, 2))));
  v = max(v, simd::Vec4f(_mm_shuffle_ps(v.v, v.v, _MM_SHUFFLE(2, 3, 0, 1))));
  return _mm_cvtss_f32(v.v);
}

template <int W, class Wide>
Bounds3 root_bounds(const Wide& bvh) {
  Bounds3 box;
  if (bvh.empty()) return box;
  const auto& r = bvh.nodes[0];
  for (int j = 0; j < W; ++j)
    if (r.child[j] != wide_empty) {
      grow(box, {r.bounds[0][j], r.bounds[2][j], r.bounds[4][j]});
      grow(box, {r.bounds[1][j], r.bounds[3][j], r.bounds[5][j]});
    }
  return box;
}

// One leaf block's box and whether it ends its leaf: what the node pass needs, written by the
// block pass so the node pass never goes back to the (cold) blocks.
struct BlockBox {
  float lo[3];
  uint32_t last;
  float hi[3];
  uint32_t pad;
};

// Pass 1, over the blocks in memory order (chunks in parallel): new vertices, then the
// block's box while it is hot. Returns the smallest invalid prim id met, or ~0u.
uint32_t refit_blocks(std::span<TriangleBlock> blocks, std::span<BlockBox> boxes,
                      BlockRewrite rewrite) {
  using simd::Vec4f;
  constexpr size_t grain = 2048;
  const size_t chunks = chunk_count(blocks.size(), grain);
  std::vector<uint32_t> bad(chunks, ~0u);
  parallel_for(0, chunks, 1, [&](size_t c0, size_t c1) {
    for (size_t c = c0; c < c1; ++c) {
      const size_t b0 = c * grain, b1 = std::min(blocks.size(), b0 + grain);
      bad[c] = rewrite(blocks.subspan(b0, b1 - b0));
      for (size_t b = b0; b < b1; ++b) {
        const TriangleBlock& blk = blocks[b];
        BlockBox& out = boxes[b];
        for (int a = 0; a < 3; ++a) {  // one row per vertex and axis: 4 lanes at once
          const Vec4f v0 = Vec4f::load(blk.v[0][a]), v1 = Vec4f::load(blk.v[1][a]),
                      v2 = Vec4f::load(blk.v[2][a]);
          out.lo[a] = hmin(min(min(v0, v1), v2));
          out.hi[a] = hmax(max(max(v0, v1), v2));
        }
        out.last = blk.prim_id[0] & block_last_bit;
      }
    }
  });
  uint32_t first_bad = ~0u;
  for (uint32_t b : bad) first_bad = std::min(first_bad, b);
  return first_bad;
}

double slot_area(float dx, float dy, float dz) {
  return double(dx) * dy + double(dy) * dz + double(dz) * dx;
}

// Pass 2, bottom-up over the nodes (children follow their parent in the array): each slot's
// box from its child node or its leaf's block boxes; the SAH cost on the way.
template <int W, class Wide>
double refit_nodes(Wide& bvh, BlockRewrite rewrite) {
  using simd::Vec4f;
  if (bvh.empty()) return 0;
  Buffer<BlockBox> boxes(bvh.blocks.size());  // every entry written by refit_blocks
  const uint32_t bad = refit_blocks({bvh.blocks.data(), bvh.blocks.size()}, boxes, rewrite);
  if (bad != ~0u)
    throw Error(
        ErrorCode::invalid_argument,
        fmt::format("refit: triangle {} is no longer valid (NaN/Inf vertex or bad index); rebuild",
                    bad));
  const float inf = INFINITY;
  double cost = 0;
  Buffer<BlockBox> node_box(bvh.nodes.size());  // each node's box, written once its slots are set
  constexpr size_t ahead = 4;  // leaf block boxes are gathers: prefetch a few nodes ahead
  for (size_t i = bvh.nodes.size(); i-- > 0;) {
    if (i >= ahead)
      for (const uint32_t ref : bvh.nodes[i - ahead].child)
        if (ref != wide_empty && (ref & wide_leaf_bit))
          __builtin_prefetch(&boxes[ref & ~wide_leaf_bit]);
    auto& node = bvh.nodes[i];
    float nlo[3] = {inf, inf, inf}, nhi[3] = {-inf, -inf, -inf};
    for (int j = 0; j < W; ++j) {
      const uint32_t ref = node.child[j];
      if (ref == wide_empty) continue;
      float lo[3], hi[3];
      double weight = 1;
      const BlockBox* b = ref & wide_leaf_bit ? &boxes[ref & ~wide_leaf_bit] : &node_box[ref];
      for (int a = 0; a < 3; ++a) lo[a] = b->lo[a], hi[a] = b->hi[a];
      if (ref & wide_leaf_bit)
        for (; !b->last; weight += 1) {
          ++b;
          for (int a = 0; a < 3; ++a) {
            lo[a] = std::min(lo[a], b->lo[a]);
            hi[a] = std::max(hi[a], b->hi[a]);
          }
        }
      set_wide_slot(node, j, Bounds3{{lo[0], lo[1], lo[2]}, {hi[0], hi[1], hi[2]}}, ref);
      cost += weight * slot_area(hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]);
      for (int a = 0; a < 3; ++a) {
        nlo[a] = std::min(nlo[a], lo[a]);
        nhi[a] = std::max(nhi[a], hi[a]);
      }
    }
    BlockBox& nb = node_box[i];
    for (int a = 0; a < 3; ++a) nb.lo[a] = nlo[a], nb.hi[a] = nhi[a];
  }
  const Bounds3 box = root_bounds<W>(bvh);
  const double root = slot_area(box.hi.x - box.lo.x, box.hi.y - box.lo.y, box.hi.z - box.lo.z);
  return root > 0 ? 1.0 + cost / root : 1.0;
}

}  // namespace

Bvh4 collapse_to_bvh4(const Bvh2& bvh, std::span<const Triangle> t, uint32_t max_leaf) {
  return collapse<4, Bvh4Node, Bvh4>(bvh, GatheredTriangles{t}, max_leaf);
}
Bvh4 collapse_to_bvh4(const Bvh2& bvh, const Scene& scene, uint32_t max_leaf) {
  return collapse<4, Bvh4Node, Bvh4>(bvh, TrianglesById(scene, bvh.prim_ids), max_leaf);
}
Bvh8 collapse_to_bvh8(const Bvh2& bvh, std::span<const Triangle> t, uint32_t max_leaf) {
  return collapse<8, Bvh8Node, Bvh8>(bvh, GatheredTriangles{t}, max_leaf);
}
Bvh8 collapse_to_bvh8(const Bvh2& bvh, const Scene& scene, uint32_t max_leaf) {
  return collapse<8, Bvh8Node, Bvh8>(bvh, TrianglesById(scene, bvh.prim_ids), max_leaf);
}
double refit_wide(Bvh4& bvh, BlockRewrite rewrite) {
  return refit_nodes<4>(bvh, rewrite);
}
double refit_wide(Bvh8& bvh, BlockRewrite rewrite) {
  return refit_nodes<8>(bvh, rewrite);
}

namespace {

template <int W, class Node>
Buffer<Node> collapse_instance_tree(const Bvh2& bvh) {
  Buffer<Node> nodes;
  if (bvh.empty()) return nodes;
  Buffer<uint8_t> flat(bvh.nodes.size());
  for (size_t i = 0; i < bvh.nodes.size(); ++i) {
    if (bvh.nodes[i].is_leaf() && bvh.nodes[i].count != 1)
      throw Error(ErrorCode::invalid_argument,
                  "instance tree: every leaf must hold one instance (max_leaf_size = 1)");
    flat[i] = bvh.nodes[i].is_leaf();
  }
  // Slot costs as plan_leaves', each leaf one instance (a block).
  Buffer<SlotCosts<W>> slots(bvh.nodes.size());
  for_each_child_first(bvh, [&](uint32_t id) {
    const Bvh2Node& node = bvh.nodes[id];
    if (flat[id])
      slots[id].fill(half_area(node));
    else
      inner_slot_costs<W>(slots[id], half_area(node), slots[node.index], slots[node.index + 1]);
  });
  nodes.reserve(bvh.nodes.size() / (W - 1) + 1);
  build_wide_nodes<W>(
      bvh, flat, std::span<const SlotCosts<W>>(slots.data(), slots.size()), nodes,
      [&](uint32_t leaf) { return wide_leaf_bit | bvh.prim_ids[bvh.nodes[leaf].index]; });
  return nodes;
}

template <int W, class Wide>
double sah(const Wide& bvh) {
  if (bvh.empty()) return 0;
  const auto area = [](const auto& n, int j) {
    const float dx = n.bounds[1][j] - n.bounds[0][j], dy = n.bounds[3][j] - n.bounds[2][j],
                dz = n.bounds[5][j] - n.bounds[4][j];
    return double(dx) * dy + double(dy) * dz + double(dz) * dx;
  };
  double cost = 0;
  const Bounds3 box = root_bounds<W>(bvh);
  const Vec3 d{box.hi.x - box.lo.x, box.hi.y - box.lo.y, box.hi.z - box.lo.z};
  const double root = double(d.x) * d.y + double(d.y) * d.z + double(d.z) * d.x;
  for (const auto& n : bvh.nodes)
    for (int j = 0; j < W; ++j) {
      const uint32_t ref = n.child[j];
      if (ref == wide_empty) continue;
      if (!(ref & wide_leaf_bit)) {
        cost += area(n, j);
        continue;
      }
      size_t blocks = 1;
      for (const TriangleBlock* b = &bvh.blocks[ref & ~wide_leaf_bit];
           !(b->prim_id[0] & block_last_bit); ++b)
        ++blocks;
      cost += area(n, j) * double(blocks);
    }
  return root > 0 ? 1.0 + cost / root : 1.0;
}

}  // namespace

Buffer<Bvh4Node> collapse_instances_bvh4(const Bvh2& bvh) {
  return collapse_instance_tree<4, Bvh4Node>(bvh);
}
Buffer<Bvh8Node> collapse_instances_bvh8(const Bvh2& bvh) {
  return collapse_instance_tree<8, Bvh8Node>(bvh);
}
Bounds3 wide_bounds(const Bvh4& bvh) {
  return root_bounds<4>(bvh);
}
Bounds3 wide_bounds(const Bvh8& bvh) {
  return root_bounds<8>(bvh);
}
double wide_sah_cost(const Bvh4& bvh) {
  return sah<4>(bvh);
}
double wide_sah_cost(const Bvh8& bvh) {
  return sah<8>(bvh);
}

void refit_bvh2(Bvh2& bvh, std::span<const Triangle> tris) {
  if (bvh.empty()) return;
  // Parents before children (breadth first), then boxes in reverse.
  std::vector<uint32_t> order{0};
  for (size_t i = 0; i < order.size(); ++i) {
    const Bvh2Node& n = bvh.nodes[order[i]];
    if (!n.is_leaf()) {
      order.push_back(n.index);
      order.push_back(n.index + 1);
    }
  }
  for (size_t i = order.size(); i-- > 0;) {
    Bvh2Node& n = bvh.nodes[order[i]];
    Bounds3 box;
    if (n.is_leaf()) {
      for (uint32_t k = n.index; k < n.index + n.count; ++k) {
        grow(box, tris[k].v0);
        grow(box, tris[k].v1);
        grow(box, tris[k].v2);
      }
    } else {
      for (uint32_t c = n.index; c < n.index + 2; ++c) {
        grow(box, bvh.nodes[c].lo);
        grow(box, bvh.nodes[c].hi);
      }
    }
    n.lo = box.lo;
    n.hi = box.hi;
  }
}

}  // namespace kestrel
