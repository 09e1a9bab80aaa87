// PNG output through stb_image_write.
#define STB_IMAGE_WRITE_IMPLEMENTATION
#define STB_IMAGE_WRITE_STATIC
#include <fmt/format.h>
#include <stb_image_write.h>

#include "core/file_io.h"
#include "kestrel/error.h"
#include "kestrel/io.h"

namespace kestrel {

void write_text_file(const std::string& path, std::string_view text) {
  AtomicFile file(path);
  file.write(text);
  file.commit();
}

void write_png(const std::string& path, int width, int height, std::span<const uint8_t> rgb) {
  if (width <= 0 || height <= 0 || rgb.size() != size_t(width) * height * 3)
    throw Error(ErrorCode::invalid_argument, fmt::format("{}: {} bytes is not a {}x{} RGB image",
                                                         path, rgb.size(), width, height));
  // Encoded in memory, then written through an AtomicFile (checked writes, renamed at the end).
  AtomicFile file(path);
  std::string png;
  auto append = [](void* context, void* data, int size) {
    static_cast<std::string*>(context)->append(static_cast<const char*>(data), size_t(size));
  };
  if (!stbi_write_png_to_func(append, &png, width, height, 3, rgb.data(), width * 3))
    throw Error(ErrorCode::io_error, fmt::format("{}: cannot encode PNG", path));
  file.write(png);
  file.commit();
}

}  // namespace kestrel
