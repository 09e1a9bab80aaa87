// ReferenceClipper: see reference_clipper.h.
#include "bvh/reference_clipper.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "core/vec.h"

namespace kestrel {

bool ReferenceClipper::split(const PrimRef& r, int axis, float pos, PrimRef& left, PrimRef& right,
                             bool& only_left) const {
  left = right = r;
  if (triangles.empty()) {
    if (!(at(r.lo, axis) < pos && pos < at(r.hi, axis))) {
      only_left = !(at(r.lo, axis) >= pos);
      return false;
    }
    at(left.hi, axis) = pos;
    at(right.lo, axis) = pos;
    return true;
  }
  const Triangle& t = triangles[r.prim_id];
  const Vec3 v[3] = {t.v0, t.v1, t.v2};
  Bounds3 lb, rb;
  for (int i = 0; i < 3; ++i) {
    const Vec3 a = v[i], b = v[i == 2 ? 0 : i + 1];
    const float pa = at(a, axis), pb = at(b, axis);
    if (pa <= pos) extend(lb, a);
    if (pa >= pos) extend(rb, a);
    if ((pa < pos && pb > pos) || (pa > pos && pb < pos)) {
      // In double: differences of floats neither overflow nor lose bits there.
      const double s = (double(pos) - pa) / (double(pb) - pa);
      Vec3 p;
      for (int k = 0; k < 3; ++k) at(p, k) = float(at(a, k) + (double(at(b, k)) - at(a, k)) * s);
      at(p, axis) = pos;
      extend(lb, p);
      extend(rb, p);
    }
  }
  // The crossing points are rounded: widen the parts by a few ulps on the other axes, so
  // their union still covers the triangle, then keep them inside the reference's box.
  auto clip = [&](Bounds3 b, PrimRef& out, bool is_left) {
    if (is_empty(b)) return false;
    for (int k = 0; k < 3; ++k) {
      if (k == axis) continue;
      const float m = 8.0f * std::numeric_limits<float>::epsilon() *
                      std::max(std::fabs(at(b.lo, k)), std::fabs(at(b.hi, k)));
      at(b.lo, k) -= m;
      at(b.hi, k) += m;
    }
    if (is_left) {
      at(b.hi, axis) = pos;
    } else {
      at(b.lo, axis) = pos;
    }
    out.lo = max(b.lo, r.lo);
    out.hi = min(b.hi, r.hi);
    return !is_empty(Bounds3{out.lo, out.hi});
  };
  const bool has_left = clip(lb, left, true), has_right = clip(rb, right, false);
  if (has_left && has_right) return true;
  only_left = has_left || !has_right;
  left = right = r;
  return false;
}

void ReferenceClipper::slab_bounds(const PrimRef& r, int axis, float lo, float width,
                                   float inv_width, int first, int last, Bounds3* parts) const {
  if (triangles.empty()) {
    for (int b = first; b <= last; ++b) parts[b] = {r.lo, r.hi};
    return;
  }
  for (int b = first; b <= last; ++b) parts[b] = Bounds3{};
  const Triangle& t = triangles[r.prim_id];
  const Vec3 v[3] = {t.v0, t.v1, t.v2};
  int slab[3];
  for (int i = 0; i < 3; ++i) {
    slab[i] = std::clamp(int((at(v[i], axis) - lo) * inv_width), first, last);
    extend(parts[slab[i]], v[i]);
  }
  for (int i = 0; i < 3; ++i) {
    const int j = i == 2 ? 0 : i + 1;
    if (slab[i] == slab[j]) continue;
    const float pa = at(v[i], axis), pb = at(v[j], axis);
    for (int k = std::min(slab[i], slab[j]) + 1; k <= std::max(slab[i], slab[j]); ++k) {
      const float plane = lo + float(k) * width;
      const Vec3 p = v[i] + (v[j] - v[i]) * ((plane - pa) / (pb - pa));
      extend(parts[k - 1], p);
      extend(parts[k], p);
    }
  }
}

}  // namespace kestrel
