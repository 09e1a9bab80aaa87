#include "common/ray_gen.h"

#include <cmath>

#include "core/splitmix.h"
#include "core/vec.h"

namespace kestrel::tools {

std::optional<RayKind> ray_kind_from_name(const std::string& name) {
  if (name == "primary") return RayKind::primary;
  if (name == "shadow") return RayKind::shadow;
  if (name == "diffuse") return RayKind::diffuse;
  return std::nullopt;
}

std::vector<Ray> primary_rays(const PinholeCamera& cam, int width, int height) {
  std::vector<Ray> rays(size_t(width) * height);
  for (int y = 0; y < height; ++y)
    for (int x = 0; x < width; ++x) rays[size_t(y) * width + x] = cam.ray(x, y, width, height);
  return rays;
}

using Rng = SplitMix64;  // enough for ray directions

std::vector<Triangle> scene_triangles(const Scene& scene) {
  std::vector<Triangle> tris;
  tris.reserve(scene.triangle_count());
  for (const TriangleMesh& mesh : scene.meshes) {
    const size_t nv = mesh.positions.size();
    for (size_t t = 0; t < mesh.triangle_count(); ++t) {
      const uint32_t* idx = &mesh.indices[3 * t];
      if (idx[0] < nv && idx[1] < nv && idx[2] < nv)
        tris.push_back({mesh.positions[idx[0]], mesh.positions[idx[1]], mesh.positions[idx[2]]});
      else
        tris.push_back({});
    }
  }
  return tris;
}

Vec3 default_light(const Bounds3& b) {
  const Vec3 c = center(b);
  return {c.x, b.hi.y - 0.45f * (b.hi.y - b.lo.y), c.z};
}

std::vector<Ray> secondary_rays(const Accel& accel, const Scene& scene,
                                const std::vector<Ray>& primary, RayKind kind, Vec3 light,
                                uint64_t seed) {
  std::vector<Hit> hits(primary.size());
  trace(accel, primary, hits, /* any_hit = */ false);
  Bounds3 box;
  if (accel.prim_count) box = accel.bounds;
  const float eps = 1e-4f * std::max(length(extent(box)), 1e-3f);
  std::vector<Ray> out;
  out.reserve(primary.size());
  Rng rng{seed};
  const std::vector<Triangle> tris = scene_triangles(scene);
  for (size_t i = 0; i < primary.size(); ++i) {
    const Hit& h = hits[i];
    if (!h.hit()) continue;
    const Ray& r = primary[i];
    const Triangle& tri = tris[h.prim_id];
    Vec3 n = normalize(cross(tri.v1 - tri.v0, tri.v2 - tri.v0));
    if (dot(n, r.dir) > 0) n = -n;
    const Vec3 p = r.org + r.dir * h.t + n * eps;
    if (kind == RayKind::shadow) {
      const Vec3 d = light - p;
      out.push_back(Ray{p, d, 0.0f, 1.0f - 1e-4f});
    } else {
      // Cosine-weighted hemisphere about n (Malley's method) in an orthonormal frame.
      const float u1 = rng.uniform(), u2 = rng.uniform();
      const float radius = std::sqrt(u1), phi = 6.28318530718f * u2;
      const Vec3 t = std::fabs(n.x) > 0.9f ? normalize(cross(n, Vec3{0, 1, 0}))
                                           : normalize(cross(n, Vec3{1, 0, 0}));
      const Vec3 bt = cross(n, t);
      const Vec3 d = t * (radius * std::cos(phi)) + bt * (radius * std::sin(phi)) +
                     n * std::sqrt(std::max(0.0f, 1.0f - u1));
      out.push_back(Ray{p, d, 0.0f, INFINITY});
    }
  }
  return out;
}

std::vector<Ray> make_rays(const Accel& accel, const Scene& scene, const PinholeCamera& cam,
                           int width, int height, RayKind kind, uint64_t seed) {
  std::vector<Ray> primary = primary_rays(cam, width, height);
  if (kind == RayKind::primary) return primary;
  return secondary_rays(accel, scene, primary, kind, default_light(scene_bounds(scene)), seed);
}

}  // namespace kestrel::tools
