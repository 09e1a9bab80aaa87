// Closest-hit and any-hit queries over an Accel, the batch entry point, and brute force.
#include "core/parallel.h"
#include "geometry/triangle_intersect.h"
#include "traverse/traverse_bvh2.h"

namespace kestrel {

namespace {
template <bool AnyHit>
Hit intersect_impl(const Accel& accel, const Ray& ray) {
  Hit hit;
  if (!is_traceable(ray)) return hit;
  const WatertightRay wr(ray);
  float tmax = ray.tmax;
  const Triangle* tris = accel.triangles.data();
  uint32_t best = invalid_id;
  traverse_bvh2<AnyHit>(accel.bvh, ray, tmax, [&](uint32_t first, uint32_t count, float& t) {
    for (uint32_t i = first; i < first + count; ++i) {
      if (intersect_triangle(wr, tris[i], ray.tmin, t, t, hit.u, hit.v)) {
        best = i;
        if constexpr (AnyHit) return true;
      }
    }
    return false;
  });
  if (best != invalid_id) {
    hit.t = tmax;
    hit.prim_id = accel.bvh.prim_ids[best];
  }
  return hit;
}
}  // namespace

Hit intersect(const Accel& accel, const Ray& ray) { return intersect_impl<false>(accel, ray); }
Hit intersect_any(const Accel& accel, const Ray& ray) { return intersect_impl<true>(accel, ray); }

void trace(const Accel& accel, std::span<const Ray> rays, std::span<Hit> hits, bool any_hit) {
  parallel_for(0, rays.size(), 1024, [&](size_t b, size_t e) {
    if (any_hit) {
      for (size_t i = b; i < e; ++i) hits[i] = intersect_impl<true>(accel, rays[i]);
    } else {
      for (size_t i = b; i < e; ++i) hits[i] = intersect_impl<false>(accel, rays[i]);
    }
  });
}

Hit intersect_brute_force(std::span<const Triangle> triangles, std::span<const uint8_t> valid,
                          const Ray& ray, bool any_hit) {
  Hit hit;
  if (!is_traceable(ray)) return hit;
  const WatertightRay wr(ray);
  float t = ray.tmax;
  for (size_t i = 0; i < triangles.size(); ++i) {
    if (!valid.empty() && !valid[i]) continue;
    if (intersect_triangle(wr, triangles[i], ray.tmin, t, t, hit.u, hit.v)) {
      hit.prim_id = uint32_t(i);
      hit.t = t;
      if (any_hit) break;
    }
  }
  return hit;
}

}  // namespace kestrel
