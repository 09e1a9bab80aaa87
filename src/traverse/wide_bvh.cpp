#include "traverse/wide_bvh.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <vector>

#include "core/check.h"
#include "core/parallel.h"
#include "core/vec.h"
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

// Subtrees of fewer nodes are planned by one task.
constexpr uint32_t plan_grain = 4096;

// Calls visit(id) for node `at` and its descendants, children before parents, subtrees in
// parallel, when the tree is laid out depth first (compact_slots' order: the descendants of
// `at` are the run [begin, end), its children's pair first, then the left child's
// descendants). A node whose children lie outside its run clears depth_first and stops
// that run (the caller then visits the whole tree serially).
template <class Visit>
void visit_subtrees(const Bvh2& bvh, const Visit& visit, uint32_t at, uint32_t begin, uint32_t end,
                    bool& depth_first) {
  const Bvh2Node& node = bvh.nodes[at];
  if (end - begin < plan_grain || node.is_leaf()) {
    if (node.is_leaf() ? begin != end : node.index != begin) {
      depth_first = false;
      return;
    }
    for (uint32_t i = end; i-- > begin;) {
      const Bvh2Node& m = bvh.nodes[i];
      if (!m.is_leaf() && (m.index <= i || m.index + 2 > end)) {
        depth_first = false;
        return;
      }
      visit(i);
    }
    visit(at);
    return;
  }
  const uint32_t l = node.index, r = l + 1;
  const Bvh2Node &left = bvh.nodes[l], &right = bvh.nodes[r];
  const uint32_t split = right.is_leaf() ? end : right.index;  // the right child's run
  if (l != begin || split < begin + 2 || split > end ||
      (!left.is_leaf() && left.index != begin + 2)) {
    depth_first = false;
    return;
  }
  bool left_ok = true, right_ok = true;
  parallel_invoke([&] { visit_subtrees(bvh, visit, l, begin + 2, split, left_ok); },
                  [&] { visit_subtrees(bvh, visit, r, split, end, right_ok); });
  depth_first = left_ok && right_ok;
  if (depth_first) visit(at);
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
  const auto visit = [&](uint32_t id) {
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
  };
  if (current_thread_count() > 1 && n >= 2 * plan_grain) {
    bool depth_first = true;
    visit_subtrees(bvh, visit, 0, 1, uint32_t(n), depth_first);
    if (!depth_first) for_each_child_first(bvh, visit);  // not the layout: once more, serially
  } else {
    for_each_child_first(bvh, visit);
  }
  plan.block_count = n > 0 ? blocks[0] : 0;
  return plan;
}

// What the node pass reads of the plan: flat[i] marks the binary subtrees that become one leaf
// slot, cost holds cost(n, i) of every binary node, blocks the triangle blocks of each
// subtree's leaves (empty: no blocks, as in the instance tree).
template <int W>
struct SlotPlan {
  std::span<const uint8_t> flat;
  std::span<const SlotCosts<W>> cost;
  std::span<const uint32_t> blocks;
};

// A wide node's slots: binary nodes, and the first block of each one's leaves.
template <int W>
struct WideSlots {
  uint32_t kid[W], first[W];
  int n = 0;
};

// The slots of the wide node over binary node `src`, whose leaves' blocks start at `first`:
// the (binary node, slots) pairs the plan gives, expanded until each holds one slot, then
// ordered by surface area, largest first (occlusion rays visit them in slot order, and a ray
// is likelier to hit a larger box: any hit on the diffuse rays, Sponza +36 %, bunny grid
// +17 %, Lamborghini +4 %; closest hit sorts by distance and is unchanged).
template <int W>
WideSlots<W> choose_slots(const Bvh2& bvh, const SlotPlan<W>& plan, uint32_t src, uint32_t first) {
  WideSlots<W> out;
  uint32_t kid[W], kid_first[W];
  if (plan.flat[src]) {
    kid[out.n] = src, kid_first[out.n++] = first;  // a one-leaf tree: the root holds one leaf
  } else {
    struct Part {
      uint32_t node;
      int slots;
      uint32_t first;
    };
    Part parts[2 * W];
    int np = 0;
    const auto split = [&](uint32_t at, int slots, uint32_t at_first) {
      const uint32_t l = bvh.nodes[at].index;
      const int k = best_split<W>(plan.cost[l], plan.cost[l + 1], slots);
      const uint32_t right_first = plan.blocks.empty() ? 0 : at_first + plan.blocks[l];
      parts[np++] = {l + 1, slots - k, right_first};
      parts[np++] = {l, k, at_first};
    };
    split(src, W, first);
    while (np > 0) {
      Part p = parts[--np];
      // cost(n, i) = cost(n, i - 1): fewer slots were as good (inner_slot_costs).
      while (p.slots > 1 && !plan.flat[p.node] &&
             plan.cost[p.node][p.slots - 1] == plan.cost[p.node][p.slots - 2])
        --p.slots;
      if (p.slots == 1 || plan.flat[p.node])
        kid[out.n] = p.node, kid_first[out.n++] = p.first;
      else
        split(p.node, p.slots, p.first);
    }
  }
  float area[W];
  for (int i = 0; i < out.n; ++i) area[i] = half_area(bvh.nodes[kid[i]]);
  int slot[W];  // an insertion sort, stable (std::stable_sort took a heap buffer per node)
  for (int i = 0; i < out.n; ++i) {
    int k = i;
    for (; k > 0 && area[slot[k - 1]] < area[i]; --k) slot[k] = slot[k - 1];
    slot[k] = i;
  }
  for (int i = 0; i < out.n; ++i) out.kid[i] = kid[slot[i]], out.first[i] = kid_first[slot[i]];
  return out;
}

// Writes the wide node over binary node `src` (its leaves' blocks from `first`) to nodes[at],
// and the wide nodes below it depth first, appended to `nodes` and referenced by their index
// there: each node's inner children allocated together, the first child's subtree next. A
// child for which defer(kid) holds is allocated but not expanded: defer_to(kid, first, index)
// hands it to the caller. leaf(kid, first) returns a leaf slot's child reference.
template <int W, class Node, class Leaf, class Defer, class DeferTo>
void write_wide_nodes(const Bvh2& bvh, const SlotPlan<W>& plan, uint32_t src, uint32_t first,
                      uint32_t at, Buffer<Node>& nodes, Leaf&& leaf, Defer&& defer,
                      DeferTo&& defer_to) {
  struct Work {
    uint32_t src, first, dst;
  };
  std::vector<Work> todo{{src, first, at}};
  while (!todo.empty()) {
    const Work work = todo.back();
    todo.pop_back();
    const WideSlots<W> s = choose_slots<W>(bvh, plan, work.src, work.first);
    Node node;
    const size_t first_new = todo.size();
    for (int j = 0; j < W; ++j) {
      if (j >= s.n) {
        const float inf = INFINITY;
        set_wide_slot(node, j, Bounds3{{inf, inf, inf}, {-inf, -inf, -inf}}, wide_empty);
        continue;
      }
      const uint32_t kid = s.kid[j];
      const Bvh2Node& k = bvh.nodes[kid];
      const Bounds3 box{k.lo, k.hi};
      if (plan.flat[kid]) {
        set_wide_slot(node, j, box, leaf(kid, s.first[j]));
        continue;
      }
      const uint32_t dst = uint32_t(nodes.size());
      nodes.emplace_back();
      set_wide_slot(node, j, box, dst);
      if (defer(kid))
        defer_to(kid, s.first[j], dst);
      else
        todo.push_back({kid, s.first[j], dst});
    }
    std::reverse(todo.begin() + first_new, todo.end());  // first child is built next
    nodes[work.dst] = node;
  }
}

// Binary subtrees of fewer primitives under a larger one are the node pass's tasks: their
// wide nodes follow the top ones', task by task (the same array for any thread count).
constexpr uint32_t node_task_prims = 4096;

// The whole node pass: the top wide nodes, then each task's, in parallel with more than one
// thread (into a buffer per task, moved into place after).
template <int W, class Node, class Leaf>
void build_wide_nodes(const Bvh2& bvh, const SlotPlan<W>& plan, std::span<const uint32_t> count,
                      Buffer<Node>& nodes, Leaf&& leaf) {
  struct Task {
    uint32_t src, first, dst;
  };
  std::vector<Task> tasks;
  nodes.emplace_back();
  write_wide_nodes<W>(
      bvh, plan, 0, 0, 0, nodes, leaf, [&](uint32_t kid) { return count[kid] < node_task_prims; },
      [&](uint32_t kid, uint32_t first, uint32_t dst) {
        tasks.push_back({kid, first, dst});
      });
  const auto never = [](uint32_t) { return false; };
  const auto none = [](uint32_t, uint32_t, uint32_t) {};
  if (current_thread_count() == 1 || tasks.size() < 2) {
    for (const Task& t : tasks)
      write_wide_nodes<W>(bvh, plan, t.src, t.first, t.dst, nodes, leaf, never, none);
    return;
  }
  std::vector<Buffer<Node>> local(tasks.size());  // [0]: the task's root, then what follows it
  parallel_for(0, tasks.size(), 1, [&](size_t b, size_t e) {
    for (size_t i = b; i < e; ++i) {
      local[i].emplace_back();
      write_wide_nodes<W>(bvh, plan, tasks[i].src, tasks[i].first, 0, local[i], leaf, never, none);
    }
  });
  std::vector<uint32_t> base(tasks.size());  // local index k > 0 goes to base + k - 1
  size_t total = nodes.size();
  for (size_t i = 0; i < tasks.size(); ++i) base[i] = uint32_t(total), total += local[i].size() - 1;
  nodes.resize(total);
  parallel_for(0, tasks.size(), 1, [&](size_t b, size_t e) {
    for (size_t i = b; i < e; ++i)
      for (size_t k = 0; k < local[i].size(); ++k) {
        Node node = local[i][k];
        for (uint32_t& ref : node.child)
          if (ref != wide_empty && !(ref & wide_leaf_bit)) ref = base[i] + ref - 1;
        nodes[k == 0 ? tasks[i].dst : base[i] + k - 1] = node;
      }
  });
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
  // The node pass places each leaf's blocks in leaf order (the binary tree's depth-first
  // order, left first) and marks them with its subtree; the block pass then reads the
  // triangles and writes the blocks front to back, in parallel (disjoint runs of out.blocks:
  // the same bytes for any thread count).
  // leaf_of_block: a leaf's subtree at its first block, `continued` at its others.
  constexpr uint32_t unplaced = ~0u, continued = ~1u;
  Buffer<uint32_t> leaf_of_block(block_count, unplaced);
  const auto leaf = [&](uint32_t subtree, uint32_t first) {
    KESTREL_CHECK(plan.blocks[subtree] > 0 && size_t(first) + plan.blocks[subtree] <= block_count,
                  "collapse: the leaf plan counted other blocks");
    leaf_of_block[first] = subtree;
    for (uint32_t b = 1; b < plan.blocks[subtree]; ++b) leaf_of_block[first + b] = continued;
    return wide_leaf_bit | first;
  };
  const SlotPlan<W> slot_plan{plan.flat, plan.slots, plan.blocks};
  build_wide_nodes<W>(bvh, slot_plan, plan.count, out.nodes, leaf);
  parallel_for(0, block_count, 2048, [&](size_t b0, size_t b1) {
    std::vector<uint32_t> prims, walk;  // leaf-order indices of a flat subtree
    for (size_t at = b0; at < b1; ++at) {
      const uint32_t subtree = leaf_of_block[at];
      if (subtree == continued) continue;  // written with its leaf's first block
      KESTREL_CHECK(subtree != unplaced, "collapse: a block no leaf placed");
      prims.clear();
      if (const uint32_t first = plan.first[subtree]; first != LeafPlan<W>::scattered) {
        for (uint32_t k = 0; k < plan.count[subtree]; ++k) prims.push_back(first + k);
      } else {
        walk.assign(1, subtree);
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
      KESTREL_CHECK(prims.size() == plan.count[subtree],
                    "collapse: a leaf holds other primitives than its plan counted");
      const uint32_t count = uint32_t(prims.size());
      const uint32_t nb = (count + 3) / 4;
      for (uint32_t b = 0; b < nb; ++b) {
        TriangleBlock& blk = out.blocks[at + b];
        for (uint32_t lane = 0; lane < 4; ++lane) {
          const uint32_t k = prims[std::min(4 * b + lane, count - 1)];  // pad with the last one
          write_block_lane(blk, int(lane), tris.at(k), bvh.prim_ids[k]);
        }
        if (b + 1 == nb) blk.prim_id[0] |= block_last_bit;
      }
    }
  });
  return out;
}

template <int W, class Wide>
Bounds3 root_bounds(const Wide& bvh) {
  Bounds3 box;
  if (bvh.empty()) return box;
  const auto& r = bvh.nodes[0];
  for (int j = 0; j < W; ++j)
    if (r.child[j] != wide_empty) {
      extend(box, Vec3{r.bounds[0][j], r.bounds[2][j], r.bounds[4][j]});
      extend(box, Vec3{r.bounds[1][j], r.bounds[3][j], r.bounds[5][j]});
    }
  return box;
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
  // Slot costs as plan_leaves', each leaf one instance (a block), and the instances under
  // each node (the node pass's tasks).
  Buffer<SlotCosts<W>> slots(bvh.nodes.size());
  Buffer<uint32_t> count(bvh.nodes.size());
  for_each_child_first(bvh, [&](uint32_t id) {
    const Bvh2Node& node = bvh.nodes[id];
    if (flat[id]) {
      slots[id].fill(half_area(node));
      count[id] = 1;
    } else {
      inner_slot_costs<W>(slots[id], half_area(node), slots[node.index], slots[node.index + 1]);
      count[id] = count[node.index] + count[node.index + 1];
    }
  });
  nodes.reserve(bvh.nodes.size() / (W - 1) + 1);
  build_wide_nodes<W>(
      bvh, SlotPlan<W>{flat, slots, {}}, count, nodes,
      [&](uint32_t leaf, uint32_t) { return wide_leaf_bit | bvh.prim_ids[bvh.nodes[leaf].index]; });
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

}  // namespace kestrel
