// Full-sweep SAH: at every node, every split between centroid-sorted neighbours on every
// axis is evaluated exactly. The quality reference for the other builders.
//
// The three axis orders are sorted once (ties broken by prim id, so the order is total) and
// kept sorted by a stable partition after each split, so a level costs O(n) instead of a
// sort per node: O(n log n) overall.
#include <algorithm>
#include <atomic>
#include <limits>
#include <vector>

#include "bvh/builders.h"
#include "bvh/node_slots.h"
#include "bvh/sah.h"
#include "core/parallel.h"
#include "core/vec.h"

namespace kestrel {

namespace {

struct SweepBuilder {
  std::span<const PrimRef> refs;
  const BuildConfig& config;
  NodeSlots& slots;
  std::vector<uint32_t> order[3];  // ref indices sorted by centroid on each axis
  std::vector<uint8_t> goes_left;  // per ref index, set for the chosen left side
  std::vector<uint32_t> scratch;   // stable-partition buffer, same ranges as `order`
  std::vector<float> right_area;   // suffix areas, same ranges as `order`

  Bounds3 ref_bounds(uint32_t i) const { return {refs[i].lo, refs[i].hi}; }

  // Returns the subtree's node count.
  uint32_t build(uint32_t slot, uint32_t pair, size_t begin, size_t end) {
    const size_t n = end - begin;
    Bounds3 node_bounds;
    for (size_t i = begin; i < end; ++i) extend(node_bounds, ref_bounds(order[0][i]));
    if (n == 1) {
      slots[slot] = Bvh2Node{node_bounds.lo, uint32_t(begin), node_bounds.hi, 1};
      return 1;
    }
    const float inv_area = inverse_area(half_area(node_bounds));
    float best_cost = std::numeric_limits<float>::infinity();
    int best_axis = 0;
    size_t best_left = n / 2;
    for (int axis = 0; axis < 3; ++axis) {
      const uint32_t* o = order[axis].data();
      Bounds3 acc;
      for (size_t i = end; i-- > begin + 1;) {
        extend(acc, ref_bounds(o[i]));
        right_area[i] = half_area(acc);
      }
      acc = Bounds3{};
      for (size_t i = begin; i + 1 < end; ++i) {
        extend(acc, ref_bounds(o[i]));
        size_t left_count = i + 1 - begin;
        float c = split_cost(config, inv_area, half_area(acc), left_count, right_area[i + 1],
                             n - left_count);
        if (c < best_cost) {
          best_cost = c;
          best_axis = axis;
          best_left = left_count;
        }
      }
    }
    if (n <= config.max_leaf_size && leaf_cost(config, n) <= best_cost) {
      slots[slot] = Bvh2Node{node_bounds.lo, uint32_t(begin), node_bounds.hi, uint32_t(n)};
      return 1;
    }
    const size_t mid = begin + best_left;
    for (size_t i = begin; i < end; ++i) goes_left[order[best_axis][i]] = i < mid;
    for (int axis = 0; axis < 3; ++axis) {
      if (axis == best_axis) continue;
      uint32_t* o = order[axis].data();
      size_t l = begin, r = mid;
      for (size_t i = begin; i < end; ++i) scratch[goes_left[o[i]] ? l++ : r++] = o[i];
      std::copy(scratch.begin() + begin, scratch.begin() + end, o + begin);
    }
    slots[slot] = Bvh2Node{node_bounds.lo, pair, node_bounds.hi, 0};
    uint32_t left_nodes = 0, right_nodes = 0;
    build_children(
        n > config.parallel_threshold, [&] { left_nodes = build(pair, pair + 2, begin, mid); },
        [&] { right_nodes = build(pair + 1, right_descendants(pair, mid - begin), mid, end); });
    return slots.set_subtree_nodes(slot, left_nodes, right_nodes);
  }
};

}  // namespace

Bvh2 build_sweep_sah(std::span<const PrimRef> refs, const BuildConfig& config) {
  const size_t n = refs.size();
  NodeSlots slots(n);
  SweepBuilder b{refs, config, slots, {}, {}, {}, {}};
  b.goes_left.resize(n);
  b.scratch.resize(n);
  b.right_area.resize(n + 1);
  for (int axis = 0; axis < 3; ++axis) {
    std::vector<float> key(n);
    for (size_t i = 0; i < n; ++i) key[i] = refs[i].lo[axis] + refs[i].hi[axis];
    b.order[axis].resize(n);
    for (size_t i = 0; i < n; ++i) b.order[axis][i] = uint32_t(i);
    std::sort(b.order[axis].begin(), b.order[axis].end(), [&](uint32_t x, uint32_t y) {
      return key[x] < key[y] || (key[x] == key[y] && refs[x].prim_id < refs[y].prim_id);
    });
  }
  b.build(0, 1, 0, n);
  std::vector<uint32_t> ids(n);
  for (size_t i = 0; i < n; ++i) ids[i] = refs[b.order[0][i]].prim_id;
  return compact_slots(slots, ids);
}

}  // namespace kestrel
