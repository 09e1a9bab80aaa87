// Image files -> Texture (RGBA8) through stb_image, for OBJ/MTL texture maps.
#define STB_IMAGE_IMPLEMENTATION
#define STB_IMAGE_STATIC
#include <fmt/format.h>
#include <stb_image.h>

#include <cmath>
#include <cstring>
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

namespace kestrel {

FloatImage load_float_image_stb(const std::string& path) {
  require_readable_file(path);
  int w = 0, h = 0, n = 0;
  const bool hdr = stbi_is_hdr(path.c_str()) != 0;
  FloatImage image;
  if (hdr) {
    std::unique_ptr<float, void (*)(void*)> px(stbi_loadf(path.c_str(), &w, &h, &n, 3), stbi_image_free);
    if (!px) throw Error(ErrorCode::parse_error, fmt::format("{}: cannot decode image ({})", path, stbi_failure_reason()));
    image = FloatImage(w, h, 3);
    std::memcpy(image.pixels.data(), px.get(), image.pixels.size() * sizeof(float));
    return image;
  }
  std::unique_ptr<stbi_uc, void (*)(void*)> px(stbi_load(path.c_str(), &w, &h, &n, 3), stbi_image_free);
  if (!px) throw Error(ErrorCode::parse_error, fmt::format("{}: cannot decode image ({})", path, stbi_failure_reason()));
  image = FloatImage(w, h, 3);
  for (size_t i = 0; i < image.pixels.size(); ++i) {
    const float c = px.get()[i] / 255.0f;  // sRGB decode
    image.pixels[i] = c <= 0.04045f ? c / 12.92f : std::pow((c + 0.055f) / 1.055f, 2.4f);
  }
  return image;
}

}  // namespace kestrel
