#include "common/views.h"

#include <cmath>
#include <filesystem>

#include "core/vec.h"
#include "kestrel/render.h"

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

PinholeCamera framing_view(const Scene& scene) {
  const Camera c = framing_camera(scene);
  return PinholeCamera{c.eye, c.target, c.vfov_degrees};
}

std::optional<PinholeCamera> named_view(const Scene& scene, const std::string& name) {
  const std::optional<Camera> c = find_view(scene, name);
  if (!c) return std::nullopt;
  return PinholeCamera{c->eye, c->target, c->vfov_degrees};
}

}  // namespace kestrel::tools
