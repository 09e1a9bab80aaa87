// Scalar Bvh2 traversal: the reference the wide SIMD kernels are tested against.
// Closest hit or any hit is chosen at compile time; leaf code is a callable, so the same
// loop serves scene triangles, instances and tests (as in madmann91/bvh).
#pragma once
#include <cmath>
#include <cstdint>

#include "kestrel/bvh.h"
#include "kestrel/trace.h"

namespace kestrel {

/// Deepest tree the fixed traversal stack supports; build_accel guarantees it.
inline constexpr uint32_t max_traversal_depth = 255;

/// Ray data for slab tests (Williams et al. 2005 with the robustness of Ize 2013).
/// inv = 1 / dir, so an axis-parallel ray has inv = +-inf; the near and far planes of each
/// axis are picked by the sign bit of dir, not by comparing the two distances. When the
/// origin lies exactly on a slab plane, (plane - org) * inf is NaN, and the comparisons
/// below ignore NaN: the slab is then inclusive, so a ray running along a box face still
/// reaches the triangles whose edges lie on that face.
struct SlabRay {
  static constexpr float far_scale = 1.00000072f;
  Vec3 org, inv, inv_far;
  int near_is_hi[3];  // 1 when dir < 0 on the axis (or -0): enter through the box's hi plane
  explicit SlabRay(const Ray& r) : org(r.org) {
    inv = {1.0f / r.dir.x, 1.0f / r.dir.y, 1.0f / r.dir.z};
    inv_far = {inv.x * far_scale, inv.y * far_scale, inv.z * far_scale};
    near_is_hi[0] = std::signbit(r.dir.x);
    near_is_hi[1] = std::signbit(r.dir.y);
    near_is_hi[2] = std::signbit(r.dir.z);
  }
  // max / min that keep `acc` when `candidate` is NaN (acc is never NaN).
  static float max_keep(float candidate, float acc) { return candidate > acc ? candidate : acc; }
  static float min_keep(float candidate, float acc) { return candidate < acc ? candidate : acc; }
  /// Entry distance into the node's box if it overlaps (tmin, tmax), else +inf.
  /// tfar uses inv_far = inv * (1 + 6 ulp): it covers 2 gamma(5) (Ize 2013) for the
  /// subtraction, both products and this rounding, with room to spare, so rounding never
  /// loses a box the watertight triangle test would hit. The wide kernels use the same
  /// operations, so they visit a leaf exactly when this traversal can.
  float enter(const Bvh2Node& n, float tmin, float tmax) const {
    const float* lo = &n.lo.x;
    const float* hi = &n.hi.x;
    float tnear = tmin, tfar = tmax;
    for (int a = 0; a < 3; ++a) {
      const float o = (&org.x)[a], i = (&inv.x)[a], f = (&inv_far.x)[a];
      const float t_near = ((near_is_hi[a] ? hi[a] : lo[a]) - o) * i;
      const float t_far = ((near_is_hi[a] ? lo[a] : hi[a]) - o) * f;
      tnear = max_keep(t_near, tnear);
      tfar = min_keep(t_far, tfar);
    }
    return tnear <= tfar ? tnear : INFINITY;
  }
};

/// Boxes are culled against the best hit so far widened by 2^-12 of its distance: a triangle
/// lying in a box face can compute a hit distance a few ulps before the box's computed entry,
/// and a second triangle hit at exactly that distance (a duplicate, a shared edge) must still
/// be reached whatever the visiting order, so the smallest-id tie rule gives one answer.
inline float cull_distance(float t) {
  return t + std::fabs(t) * 0x1p-12f;
}

/// Walks the BVH nearest child first. leaf(first, count, tmax) tests prims
/// [first, first + count) of bvh.prim_ids, may lower tmax, and returns true to stop (any hit).
template <bool AnyHit, class LeafFn>
inline void traverse_bvh2(const Bvh2& bvh, const Ray& ray, float& tmax, LeafFn&& leaf) {
  if (bvh.empty()) return;
  const SlabRay sr(ray);
  const Bvh2Node* nodes = bvh.nodes.data();
  uint32_t stack[max_traversal_depth + 1];
  int top = 0;
  if (sr.enter(nodes[0], ray.tmin, tmax) == INFINITY) return;
  uint32_t current = 0;
  while (true) {
    const Bvh2Node& node = nodes[current];
    if (node.is_leaf()) {
      if (leaf(node.index, node.count, tmax) && AnyHit) return;
    } else {
      const uint32_t a = node.index, b = node.index + 1;
      const float cull = cull_distance(tmax);
      float ta = sr.enter(nodes[a], ray.tmin, cull);
      float tb = sr.enter(nodes[b], ray.tmin, cull);
      if (ta != INFINITY) {
        if (tb != INFINITY) {
          // Both: go to the nearer, keep the farther.
          if (tb < ta) {
            stack[top++] = a;
            current = b;
          } else {
            stack[top++] = b;
            current = a;
          }
        } else {
          current = a;
        }
        continue;
      }
      if (tb != INFINITY) {
        current = b;
        continue;
      }
    }
    if (top == 0) return;
    current = stack[--top];
  }
}

}  // namespace kestrel
