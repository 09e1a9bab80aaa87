#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>

#include <sys/stat.h>

#include "core/file_io.h"
#include "io/loaders.h"
#include "kestrel/error.h"

namespace kestrel {

void require_readable_file(const std::string& path) {
  struct stat st {};
  if (::stat(path.c_str(), &st) != 0)
    throw Error(ErrorCode::file_not_found, fmt::format("{}: no such file", path));
  regular_file_size(path);  // a folder, FIFO or device: an Error saying which
  std::ifstream f(path, std::ios::binary);
  if (!f) throw Error(ErrorCode::file_not_found, fmt::format("{}: cannot be opened", path));
}

const char* light_type_name(Light::Type type) {
  switch (type) {
    case Light::Type::point:
      return "point";
    case Light::Type::spot:
      return "spot";
    case Light::Type::directional:
      return "directional";
  }
  return "?";
}

std::string light_problem(const Light& l) {
  const auto finite = [](Vec3 v) {
    return std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z);
  };
  if (!finite(l.color) || !std::isfinite(l.intensity) || !std::isfinite(l.range))
    return "a NaN or Inf colour, intensity or range";
  if (l.color.x < 0 || l.color.y < 0 || l.color.z < 0 || l.intensity < 0 || l.range < 0)
    return fmt::format("negative colour, intensity ({}) or range ({})", l.intensity, l.range);
  if (l.type != Light::Type::directional && !finite(l.position)) return "a NaN or Inf position";
  if (l.type != Light::Type::point) {
    const float len2 = l.direction.x * l.direction.x + l.direction.y * l.direction.y +
                       l.direction.z * l.direction.z;
    if (!std::isfinite(len2) || !(std::fabs(len2 - 1.0f) < 1e-3f))
      return "its direction is not a finite unit vector (a NaN, zero or singular node transform)";
  }
  if (l.type == Light::Type::spot &&
      !(std::isfinite(l.inner_cone) && std::isfinite(l.outer_cone) && l.inner_cone >= 0 &&
        l.inner_cone < l.outer_cone && l.outer_cone <= 1.5707964f))
    return fmt::format("spot cone angles inner {} / outer {} are not 0 <= inner < outer <= pi/2",
                       l.inner_cone, l.outer_cone);
  return {};
}

bool is_gltf_path(const std::string& path) {
  const std::string ext = lower_extension(path);
  return ext == ".gltf" || ext == ".glb";
}

namespace {

// Triangles that will never be built (NaN/Inf vertices, bad indices, zero area) as a warning
// with the counts, so a damaged mesh does not render silently with holes.
Scene with_validation_warning(Scene scene) {
  const std::string w = skipped_triangles_warning(scene.source, validate_scene(scene).report);
  if (!w.empty()) scene.warnings.push_back(w);
  return scene;
}

}  // namespace

std::string skipped_triangles_warning(const std::string& source, const ValidationReport& r) {
  if (r.valid_triangle_count == r.triangle_count) return {};
  return fmt::format(
      "{}: {} of {} triangles skipped ({} with a NaN or Inf vertex, {} with an index past "
      "the vertices, {} of zero area)",
      source, r.triangle_count - r.valid_triangle_count, r.triangle_count,
      r.nonfinite_triangle_count, r.bad_index_triangle_count, r.degenerate_triangle_count);
}

Scene load_scene(const std::string& path) {
  constexpr std::string_view builtin_prefix = "builtin:";
  if (path.rfind(builtin_prefix, 0) == 0)
    return make_builtin_scene(path.substr(builtin_prefix.size()));
  const std::string ext = lower_extension(path);
  if (ext == ".obj") return with_validation_warning(load_obj(path));
  if (is_gltf_path(path)) return with_validation_warning(load_gltf(path));
  require_readable_file(path);
  throw Error(
      ErrorCode::unsupported,
      fmt::format("{}: unknown scene format '{}' (expected .obj, .gltf, .glb or builtin:NAME)",
                  path, ext));
}

}  // namespace kestrel
