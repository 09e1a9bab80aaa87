#include "common/views.h"

#include <fmt/format.h>

#include <cmath>
#include <filesystem>

#include "core/vec.h"
#include "kestrel/error.h"
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

CameraPath camera_path_for(const Asset& asset, const std::string& path_spec,
                           const std::string& view_name) {
  if (path_spec.rfind("orbit", 0) != 0) {
    if (!view_name.empty())
      throw Error(ErrorCode::invalid_argument, "--view is only for --path orbit[:DEG]");
    return CameraPath::load(path_spec);
  }
  double degrees = 360;
  if (path_spec != "orbit") {
    char* end = nullptr;
    const std::string arg = path_spec.size() > 6 && path_spec[5] == ':' ? path_spec.substr(6) : "";
    degrees = std::strtod(arg.c_str(), &end);
    if (arg.empty() || end != arg.c_str() + arg.size())
      throw Error(ErrorCode::invalid_argument,
                  fmt::format("--path '{}': expected a JSON file or orbit[:DEGREES]", path_spec));
  }
  return CameraPath::orbit(start_camera_for(asset, view_name), degrees);
}

Camera start_camera_for(const Asset& asset, const std::string& view_name) {
  std::string view = view_name;
  if (view.empty()) view = find_view(asset, "front") ? "front" : "framing";
  const auto c = find_view(asset, view);
  if (!c)
    throw Error(ErrorCode::invalid_argument,
                fmt::format("{}: no view named '{}'", asset.source(), view));
  return *c;
}

}  // namespace kestrel::tools
