// Equal-count split on the largest centroid axis (nth_element). The cheapest top-down
// builder; leaves are made when a node fits max_leaf_size and the median split would not
// beat the leaf's SAH cost.
#include <algorithm>
#include <atomic>
#include <vector>

#include "bvh/builders.h"
#include "bvh/node_slots.h"
#include "bvh/sah.h"
#include "core/parallel.h"
#include "core/vec.h"

namespace kestrel {

namespace {

struct MedianBuilder {
  Buffer<PrimRef>& refs;
  const BuildConfig& config;
  NodeSlots& slots;

  Bounds3 bounds_of(size_t begin, size_t end, Bounds3* centroids) const {
    Bounds3 b, c;
    for (size_t i = begin; i < end; ++i) {
      extend(b, Bounds3{refs[i].lo, refs[i].hi});
      extend(c, (refs[i].lo + refs[i].hi) * 0.5f);
    }
    if (centroids) *centroids = c;
    return b;
  }

  uint32_t make_leaf(uint32_t slot, const Bounds3& b, size_t begin, size_t end) {
    slots[slot] = Bvh2Node{b.lo, uint32_t(begin), b.hi, uint32_t(end - begin)};
    return 1;
  }

  // Returns the subtree's node count.
  uint32_t build(uint32_t slot, uint32_t pair, size_t begin, size_t end) {
    Bounds3 centroid_bounds;
    const Bounds3 node_bounds = bounds_of(begin, end, &centroid_bounds);
    const size_t n = end - begin;
    if (n == 1) return make_leaf(slot, node_bounds, begin, end);
    const int axis = max_axis(extent(centroid_bounds));
    const size_t mid = begin + n / 2;
    std::nth_element(refs.begin() + begin, refs.begin() + mid, refs.begin() + end,
                     [axis](const PrimRef& a, const PrimRef& b) {
                       float ca = a.lo[axis] + a.hi[axis], cb = b.lo[axis] + b.hi[axis];
                       return ca < cb || (ca == cb && a.prim_id < b.prim_id);
                     });
    if (n <= config.max_leaf_size) {
      Bounds3 l = bounds_of(begin, mid, nullptr), r = bounds_of(mid, end, nullptr);
      float split = split_cost(config, inverse_area(half_area(node_bounds)), half_area(l),
                               mid - begin, half_area(r), end - mid);
      if (leaf_cost(config, n) <= split) return make_leaf(slot, node_bounds, begin, end);
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

Bvh2 build_median(std::span<const PrimRef> input, const BuildConfig& config) {
  Buffer<PrimRef> refs(input.begin(), input.end());
  NodeSlots slots(refs.size());
  MedianBuilder builder{refs, config, slots};
  builder.build(0, 1, 0, refs.size());
  std::vector<uint32_t> ids(refs.size());
  for (size_t i = 0; i < refs.size(); ++i) ids[i] = refs[i].prim_id;
  return compact_slots(slots, ids);
}

}  // namespace kestrel
