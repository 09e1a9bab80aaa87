// kestrel public API: rays, hits, an acceleration structure over a scene, and tracing.
#pragma once
#include <cstdint>
#include <limits>
#include <span>

#include "kestrel/bvh.h"
#include "kestrel/scene.h"

namespace kestrel {

/// A ray: points org + t * dir for t in (tmin, tmax). dir need not be normalised; t is in
/// units of dir. A ray with a NaN or Inf component, or a zero direction, never hits.
struct Ray {
  Vec3 org;
  Vec3 dir;
  float tmin = 0.0f;
  float tmax = std::numeric_limits<float>::infinity();
};

/// Id of "no primitive".
inline constexpr uint32_t invalid_id = 0xFFFFFFFFu;

/// A hit: distance t (units of dir) and the global prim id; a miss has t = +inf and
/// prim_id = invalid_id. u, v are barycentrics of vertices 1 and 2.
struct Hit {
  float t = std::numeric_limits<float>::infinity();
  uint32_t prim_id = invalid_id;
  float u = 0, v = 0;
  bool hit() const { return prim_id != invalid_id; }
};

/// A triangle as stored for intersection (vertices copied in BVH leaf order).
struct Triangle {
  Vec3 v0, v1, v2;
};

/// A scene ready to trace: the BVH over its valid triangles and their vertices in leaf order.
struct Accel {
  Bvh2 bvh;
  Buffer<Triangle> triangles;       ///< triangles[i] is primitive bvh.prim_ids[i]
  SceneValidation validation;
  double build_ms = 0;              ///< prim refs + builder + triangle copy, wall clock
};

/// Builds an Accel over a scene's valid triangles (invalid ones are counted and skipped).
Accel build_accel(const Scene& scene, const BuildConfig& config);

/// Closest hit along the ray (watertight, Woop et al. 2013), or a miss.
Hit intersect(const Accel& accel, const Ray& ray);
/// Any hit in (tmin, tmax): t of the hit found (not necessarily the closest), or a miss.
Hit intersect_any(const Accel& accel, const Ray& ray);

/// Traces a batch, spread over the current thread pool in chunks.
void trace(const Accel& accel, std::span<const Ray> rays, std::span<Hit> hits, bool any_hit);

/// Reference: every valid triangle against the ray (the tests' oracle).
Hit intersect_brute_force(std::span<const Triangle> triangles, std::span<const uint8_t> valid,
                          const Ray& ray, bool any_hit);

}  // namespace kestrel
