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

/// Ray data for slab tests. Zero direction components are replaced by a tiny value of the
/// same sign, so 1/d is finite and (lo - org) * inv never makes 0 * inf = NaN for rays
/// parallel to an axis or lying in a slab plane.
struct SlabRay {
  Vec3 org, inv;
  explicit SlabRay(const Ray& r) : org(r.org) {
    auto safe_inv = [](float d) {
      constexpr float tiny = 1e-30f;
      return 1.0f / (std::fabs(d) < tiny ? std::copysign(tiny, d) : d);
    };
    inv = {safe_inv(r.dir.x), safe_inv(r.dir.y), safe_inv(r.dir.z)};
  }
  /// Entry distance into the node's box if it overlaps (tmin, tmax), else +inf.
  /// tfar is scaled by 1 + 2 gamma(3) (Ize 2013) so rounding never loses a box the
  /// watertight triangle test would hit.
  float enter(const Bvh2Node& n, float tmin, float tmax) const {
    float tx0 = (n.lo.x - org.x) * inv.x, tx1 = (n.hi.x - org.x) * inv.x;
    float ty0 = (n.lo.y - org.y) * inv.y, ty1 = (n.hi.y - org.y) * inv.y;
    float tz0 = (n.lo.z - org.z) * inv.z, tz1 = (n.hi.z - org.z) * inv.z;
    float tnear = std::fmax(std::fmax(std::fmin(tx0, tx1), std::fmin(ty0, ty1)), std::fmax(std::fmin(tz0, tz1), tmin));
    float tfar = std::fmin(std::fmin(std::fmax(tx0, tx1), std::fmax(ty0, ty1)), std::fmax(tz0, tz1));
    tfar = std::fmin(tfar * 1.0000003576f, tmax);
    return tnear <= tfar ? tnear : INFINITY;
  }
};

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
      float ta = sr.enter(nodes[a], ray.tmin, tmax);
      float tb = sr.enter(nodes[b], ray.tmin, tmax);
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
