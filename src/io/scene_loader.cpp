#include <fmt/format.h>

#include <algorithm>
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

namespace {

std::string lower_extension(const std::string& path) {
  std::string ext = std::filesystem::path(path).extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(),
                 [](unsigned char c) { return char(std::tolower(c)); });
  return ext;
}

}  // namespace

bool is_gltf_path(const std::string& path) {
  const std::string ext = lower_extension(path);
  return ext == ".gltf" || ext == ".glb";
}

namespace {

// Triangles that will never be built (NaN/Inf vertices, bad indices, zero area) as a warning
// with the counts, so a damaged mesh does not render silently with holes.
Scene with_validation_warning(Scene scene) {
  const ValidationReport r = validate_scene(scene).report;
  if (r.valid_triangle_count != r.triangle_count)
    scene.warnings.push_back(fmt::format(
        "{}: {} of {} triangles skipped ({} with a NaN or Inf vertex, {} with an index past "
        "the vertices, {} of zero area)",
        scene.source, r.triangle_count - r.valid_triangle_count, r.triangle_count,
        r.nonfinite_triangle_count, r.bad_index_triangle_count, r.degenerate_triangle_count));
  return scene;
}

}  // namespace

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
