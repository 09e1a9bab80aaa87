#include <fmt/format.h>

#include <algorithm>
#include <filesystem>
#include <fstream>

#include "io/loaders.h"
#include "kestrel/error.h"

namespace kestrel {

void require_readable_file(const std::string& path) {
  std::error_code ec;
  if (!std::filesystem::is_regular_file(path, ec))
    throw Error(ErrorCode::file_not_found, fmt::format("{}: no such file", path));
  std::ifstream f(path, std::ios::binary);
  if (!f) throw Error(ErrorCode::file_not_found, fmt::format("{}: cannot be opened", path));
}

namespace {

std::string lower_extension(const std::string& path) {
  std::string ext = std::filesystem::path(path).extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return char(std::tolower(c)); });
  return ext;
}

}  // namespace

bool is_gltf_path(const std::string& path) {
  const std::string ext = lower_extension(path);
  return ext == ".gltf" || ext == ".glb";
}

Scene load_scene(const std::string& path) {
  constexpr std::string_view builtin_prefix = "builtin:";
  if (path.rfind(builtin_prefix, 0) == 0) return make_builtin_scene(path.substr(builtin_prefix.size()));
  const std::string ext = lower_extension(path);
  if (ext == ".obj") return load_obj(path);
  if (is_gltf_path(path)) return load_gltf(path);
  require_readable_file(path);
  throw Error(ErrorCode::unsupported,
              fmt::format("{}: unknown scene format '{}' (expected .obj, .gltf, .glb or builtin:NAME)", path, ext));
}

}  // namespace kestrel
