// Ray sets for benchmarks and tests: primary rays from a camera, shadow rays (any hit)
// towards a point light and diffuse (cosine-weighted) bounce rays from the primary hits.
#pragma once
#include <cstdint>
#include <string>
#include <vector>

#include "common/views.h"
#include "kestrel/trace.h"

namespace kestrel::tools {

enum class RayKind { primary, shadow, diffuse };
/// "primary", "shadow", "diffuse".
std::optional<RayKind> ray_kind_from_name(const std::string& name);

/// One ray per pixel, row by row, through pixel centres.
std::vector<Ray> primary_rays(const PinholeCamera& cam, int width, int height);

/// Secondary rays from the primary hits: for each hit, a shadow ray to `light` (tmax just
/// short of the light) or a cosine-distributed diffuse ray about the geometric normal
/// facing the incoming ray. Misses produce no ray. Origins are offset along the normal by a
/// small fraction of the scene size. Deterministic for a seed.
std::vector<Ray> secondary_rays(const Accel& accel, const Scene& scene,
                                const std::vector<Ray>& primary, RayKind kind, Vec3 light,
                                uint64_t seed);

/// Every triangle of the scene by global prim id (bad-index triangles are zero), so a
/// hit's triangle is scene_triangles(scene)[hit.prim_id].
std::vector<Triangle> scene_triangles(const Scene& scene);

/// The default point light: above the centre of the scene box, 45% of its height from the top
/// (inside enclosed scenes such as Sponza and the Cornell box).
Vec3 default_light(const Bounds3& scene_box);

/// The whole ray set of a kind for a camera (primary, or primary then secondary).
std::vector<Ray> make_rays(const Accel& accel, const Scene& scene, const PinholeCamera& cam,
                           int width, int height, RayKind kind, uint64_t seed);

}  // namespace kestrel::tools
