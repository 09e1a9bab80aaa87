// Image files -> Texture (RGBA8) through stb_image, for OBJ/MTL texture maps.
#define STB_IMAGE_IMPLEMENTATION
#define STB_IMAGE_STATIC
#include <fmt/format.h>
#include <stb_image.h>

#include <memory>

#include "io/loaders.h"
#include "kestrel/error.h"

namespace kestrel {

Texture load_texture(const std::string& path) {
  require_readable_file(path);
  int w = 0, h = 0, channels = 0;
  std::unique_ptr<stbi_uc, void (*)(void*)> pixels(stbi_load(path.c_str(), &w, &h, &channels, 4), stbi_image_free);
  if (!pixels)
    throw Error(ErrorCode::parse_error, fmt::format("{}: cannot decode image ({})", path, stbi_failure_reason()));
  Texture t;
  t.name = path;
  t.width = w;
  t.height = h;
  t.rgba.assign(pixels.get(), pixels.get() + size_t(w) * h * 4);
  return t;
}

}  // namespace kestrel
