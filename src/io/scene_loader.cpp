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

Scene load_scene(const std::string& path) {
  constexpr std::string_view builtin_prefix = "builtin:";
  if (path.rfind(builtin_prefix, 0) == 0) return make_builtin_scene(path.substr(builtin_prefix.size()));
  std::string ext = std::filesystem::path(path).extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return char(std::tolower(c)); });
  if (ext == ".obj") return load_obj(path);
  if (ext == ".gltf" || ext == ".glb") return load_gltf(path);
  require_readable_file(path);
  throw Error(ErrorCode::unsupported,
              fmt::format("{}: unknown scene format '{}' (expected .obj, .gltf, .glb or builtin:NAME)", path, ext));
}

}  // namespace kestrel
