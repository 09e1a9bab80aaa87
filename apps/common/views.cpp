#include "common/views.h"

#include <cmath>
#include <filesystem>

#include "core/vec.h"

namespace kestrel::tools {

Ray PinholeCamera::ray(int px, int py, int width, int height, float jx, float jy) const {
  const Vec3 forward = normalize(target - eye);
  Vec3 right = cross(forward, Vec3{0, 1, 0});
  if (length(right) < 1e-6f) right = Vec3{1, 0, 0};
  right = normalize(right);
  const Vec3 up = cross(right, forward);
  const float tan_half = std::tan(vfov_degrees * 0.5f * 3.14159265358979f / 180.0f);
  const float aspect = float(width) / float(height);
  const float sx = (2.0f * (float(px) + jx) / float(width) - 1.0f) * tan_half * aspect;
  const float sy = (1.0f - 2.0f * (float(py) + jy) / float(height)) * tan_half;
  return Ray{eye, forward + right * sx + up * sy, 0.0f, INFINITY};
}

Bounds3 scene_bounds(const Scene& scene) {
  Bounds3 b;
  for (const TriangleMesh& m : scene.meshes)
    for (uint32_t i : m.indices)
      if (i < m.positions.size() && is_finite(m.positions[i])) extend(b, m.positions[i]);
  return b;
}

PinholeCamera framing_view(const Scene& scene) {
  const Bounds3 b = scene_bounds(scene);
  PinholeCamera cam;
  cam.vfov_degrees = 45.0f;
  cam.target = is_empty(b) ? Vec3{0, 0, 0} : center(b);
  const float r = is_empty(b) ? 1.0f : std::max(0.5f * length(extent(b)), 1e-6f);
  const float dist = r / std::sin(cam.vfov_degrees * 0.5f * 3.14159265358979f / 180.0f);
  cam.eye = cam.target + normalize(Vec3{0.3f, 0.35f, -1.0f}) * dist;
  return cam;
}

std::optional<PinholeCamera> named_view(const Scene& scene, const std::string& name) {
  if (name == "framing" || name.empty()) return framing_view(scene);
  const std::string stem = std::filesystem::path(scene.source).stem().string();
  if (name == "inside" && stem == "sponza")
    return PinholeCamera{{14.4499f, 6.89415f, -1.18547f}, {13.4563f, 6.78438f, -1.15861f}, 90.0f};
  if (name == "front" && scene.source == "builtin:cornell_box")
    return PinholeCamera{{0.278f, 0.273f, -0.8f}, {0.278f, 0.273f, 0.0f}, 39.3f};
  return std::nullopt;
}

}  // namespace kestrel::tools
