// Cutting the references of the spatial-split builder at axis-aligned planes: the part of a
// reference's triangle on either side of a plane, or in each slab between planes.
#pragma once
#include <span>

#include "kestrel/bvh.h"

namespace kestrel {

/// A Vec3's coordinate on `axis` (0, 1, 2).
inline float& at(Vec3& v, int axis) {
  return (&v.x)[axis];
}
inline float at(const Vec3& v, int axis) {
  return (&v.x)[axis];
}

struct ReferenceClipper {
  std::span<const Triangle> triangles;  ///< by prim id; empty: the boxes are cut as boxes

  /// Splits r at `pos` on `axis` into the parts of its primitive on either side, each within
  /// r's box and covering that side's part (crossing points computed in double, the parts
  /// widened by 8 ulps on the other axes for their rounding). Returns false when one side
  /// holds nothing of the primitive; `left` and `right` are then r itself and `only_left`
  /// says which side it lies on.
  bool split(const PrimRef& r, int axis, float pos, PrimRef& left, PrimRef& right,
             bool& only_left) const;

  /// The bounds of r's primitive in each slab b of `width` (= 1 / inv_width) from `lo` on
  /// `axis`, for b in [first, last], into parts[b], in one pass over the triangle:
  /// its vertices go to their slabs, each edge's crossing points to the slabs on both sides.
  /// An estimate for the builder's sweep (float, not widened, not yet clipped to r's box or
  /// the slab); the chosen plane is then cut exactly by split().
  void slab_bounds(const PrimRef& r, int axis, float lo, float width, float inv_width, int first,
                   int last, Bounds3* parts) const;
};

}  // namespace kestrel
