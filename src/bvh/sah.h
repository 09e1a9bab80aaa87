// Surface area heuristic (Goldsmith & Salmon 1987, MacDonald & Booth 1990) helpers.
// Costs are kept in absolute units (area x cost): C(leaf) = Ci * A * N,
// C(inner) = Ct * A + C(left) + C(right); the tree's SAH cost is C(root) / A(root).
#pragma once
#include "kestrel/bvh.h"

namespace kestrel {

/// 1 / A for split_cost (0 for a zero-area node: every split then costs Ct).
inline float inverse_area(float node_area) {
  return node_area > 0.0f ? 1.0f / node_area : 0.0f;
}

/// A split's cost relative to making a leaf, both divided by the node's area A:
/// split = Ct + Ci * (Al * Nl + Ar * Nr) / A, leaf = Ci * N. Takes 1 / A (inverse_area), so
/// sweeps over many candidate splits divide once.
inline float split_cost(const BuildConfig& c, float inv_node_area, float left_area,
                        size_t left_count, float right_area, size_t right_count) {
  return c.traversal_cost + c.intersection_cost *
                                (left_area * float(left_count) + right_area * float(right_count)) *
                                inv_node_area;
}
inline float leaf_cost(const BuildConfig& c, size_t count) {
  return c.intersection_cost * float(count);
}

}  // namespace kestrel
