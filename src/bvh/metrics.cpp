// SAH cost and structure figures of a Bvh2.
#include <algorithm>

#include "core/vec.h"
#include "kestrel/bvh.h"

namespace kestrel {

namespace {
// In double: float areas overflow for boxes wider than ~1.8e19 (valid, finite scenes).
double half_area_double(const Bvh2Node& n) {
  if (n.lo.x > n.hi.x || n.lo.y > n.hi.y || n.lo.z > n.hi.z) return 0.0;
  const double dx = double(n.hi.x) - n.lo.x, dy = double(n.hi.y) - n.lo.y,
               dz = double(n.hi.z) - n.lo.z;
  return dx * dy + dy * dz + dz * dx;
}
}  // namespace

uint32_t max_depth(const Bvh2& bvh) {
  if (bvh.empty()) return 0;
  // Every kestrel builder puts children after their parent: then one forward pass over the
  // array gives each node its depth (no stack, no branch on leaf or not). Other orders: a
  // depth-first walk.
  const size_t n = bvh.nodes.size();
  Buffer<uint32_t> depth(n);  // pooled: a rebuilt scene does not fault it in again
  std::fill(depth.begin(), depth.end(), 0u);
  uint32_t deepest = 0;
  size_t i = 0;
  for (; i < n; ++i) {
    const Bvh2Node& node = bvh.nodes[i];
    deepest = std::max(deepest, depth[i]);
    if (node.is_leaf()) continue;
    if (node.index <= i || node.index + 1 >= n) break;  // not parents first
    depth[node.index] = depth[node.index + 1] = depth[i] + 1;
  }
  if (i == n) return deepest;
  deepest = 0;
  std::vector<std::pair<uint32_t, uint32_t>> stack{{0, 0}};
  while (!stack.empty()) {
    auto [k, d] = stack.back();
    stack.pop_back();
    const Bvh2Node& node = bvh.nodes[k];
    if (node.is_leaf()) {
      deepest = std::max(deepest, d);
    } else {
      stack.push_back({node.index, d + 1});
      stack.push_back({node.index + 1, d + 1});
    }
  }
  return deepest;
}

BvhMetrics compute_metrics(const Bvh2& bvh, const BuildConfig& config) {
  BvhMetrics m;
  m.node_count = bvh.nodes.size();
  m.prim_count = bvh.prim_ids.size();
  if (bvh.empty()) return m;
  m.leaf_size_histogram.assign(config.max_leaf_size + 1, 0);
  double inner_area = 0, leaf_area_prims = 0;
  double depth_sum = 0;
  std::vector<std::pair<uint32_t, uint32_t>> stack{{0, 0}};
  while (!stack.empty()) {
    auto [i, depth] = stack.back();
    stack.pop_back();
    const Bvh2Node& node = bvh.nodes[i];
    const double area = half_area_double(node);
    m.max_depth = std::max(m.max_depth, depth);
    if (node.is_leaf()) {
      ++m.leaf_count;
      leaf_area_prims += area * node.count;
      depth_sum += depth;
      if (node.count >= m.leaf_size_histogram.size())
        m.leaf_size_histogram.resize(node.count + 1, 0);
      ++m.leaf_size_histogram[node.count];
    } else {
      ++m.inner_count;
      inner_area += area;
      stack.push_back({node.index, depth + 1});
      stack.push_back({node.index + 1, depth + 1});
    }
  }
  const double root_area = half_area_double(bvh.nodes[0]);
  const double norm = root_area > 0 ? 1.0 / root_area : 0.0;
  m.sah_cost =
      (config.traversal_cost * inner_area + config.intersection_cost * leaf_area_prims) * norm;
  m.sah_cost_unit = (inner_area + leaf_area_prims) * norm;
  m.mean_leaf_depth = m.leaf_count ? depth_sum / m.leaf_count : 0.0;
  m.bytes_per_prim =
      m.prim_count ? double(m.node_count * sizeof(Bvh2Node) + m.prim_count * sizeof(uint32_t)) /
                         double(m.prim_count)
                   : 0.0;
  return m;
}

}  // namespace kestrel
