// Helpers on the public Vec3 / Bounds3 types for kestrel's own code (the arithmetic itself,
// + - * /, dot, cross, length, normalize, is public in kestrel/types.h).
#pragma once
#include <algorithm>
#include <cmath>

#include "kestrel/types.h"

namespace kestrel {

inline Vec3 min(Vec3 a, Vec3 b) {
  return {std::min(a.x, b.x), std::min(a.y, b.y), std::min(a.z, b.z)};
}
inline Vec3 max(Vec3 a, Vec3 b) {
  return {std::max(a.x, b.x), std::max(a.y, b.y), std::max(a.z, b.z)};
}
inline bool is_finite(Vec3 a) {
  return std::isfinite(a.x) && std::isfinite(a.y) && std::isfinite(a.z);
}
inline int max_axis(Vec3 a) {
  return a.x >= a.y ? (a.x >= a.z ? 0 : 2) : (a.y >= a.z ? 1 : 2);
}

inline void extend(Bounds3& b, Vec3 p) {
  b.lo = min(b.lo, p);
  b.hi = max(b.hi, p);
}
inline void extend(Bounds3& b, const Bounds3& o) {
  b.lo = min(b.lo, o.lo);
  b.hi = max(b.hi, o.hi);
}
inline Bounds3 merge(const Bounds3& a, const Bounds3& b) {
  return {min(a.lo, b.lo), max(a.hi, b.hi)};
}
inline bool is_empty(const Bounds3& b) {
  return b.lo.x > b.hi.x || b.lo.y > b.hi.y || b.lo.z > b.hi.z;
}
inline Vec3 extent(const Bounds3& b) {
  return b.hi - b.lo;
}
inline Vec3 center(const Bounds3& b) {
  return (b.lo + b.hi) * 0.5f;
}
/// Half the surface area (SAH uses ratios, so the factor 2 never matters); 0 when empty.
inline float half_area(const Bounds3& b) {
  if (is_empty(b)) return 0.0f;
  Vec3 d = extent(b);
  return d.x * d.y + d.y * d.z + d.z * d.x;
}
inline bool contains(const Bounds3& outer, const Bounds3& inner) {
  return inner.lo.x >= outer.lo.x && inner.lo.y >= outer.lo.y && inner.lo.z >= outer.lo.z &&
         inner.hi.x <= outer.hi.x && inner.hi.y <= outer.hi.y && inner.hi.z <= outer.hi.z;
}

}  // namespace kestrel
