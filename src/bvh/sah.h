// Surface area heuristic (Goldsmith & Salmon 1987, MacDonald & Booth 1990) helpers.
// Costs are kept in absolute units (area x cost): C(leaf) = Ci * A * N,
// C(inner) = Ct * A + C(left) + C(right); the tree's SAH cost is C(root) / A(root).
#pragma once
#include "kestrel/bvh.h"

namespace kestrel {

/// A split's cost relative to making a leaf, both divided by the node's area:
/// split = Ct + Ci * (Al * Nl + Ar * Nr) / A, leaf = Ci * N.
inline float split_cost(const BuildConfig& c, float node_area, float left_area, size_t left_count,
                        float right_area, size_t right_count) {
  float inv = node_area > 0.0f ? 1.0f / node_area : 0.0f;
  return c.traversal_cost +
         c.intersection_cost * (left_area * float(left_count) + right_area * float(right_count)) * inv;
}
inline float leaf_cost(const BuildConfig& c, size_t count) {
  return c.intersection_cost * float(count);
}

}  // namespace kestrel
