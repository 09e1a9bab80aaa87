// Image files -> Texture (RGBA8) or float RGB through stb_image, for texture maps and
// environments. The file is read whole (bounded), its header checked -- dimensions and the
// size it would decode to against what a file of its length can hold -- before stb_image
// allocates anything.
#define STB_IMAGE_IMPLEMENTATION
#define STB_IMAGE_STATIC
#define STBI_MAX_DIMENSIONS 32768
// Only the formats textures and environments come in: less of stb_image for a hostile file
// to reach (its GIF, PSD, PIC and PNM decoders are left out).
#define STBI_ONLY_PNG
#define STBI_ONLY_JPEG
#define STBI_ONLY_HDR
#define STBI_ONLY_BMP
#define STBI_ONLY_TGA
#include <fmt/format.h>
#include <stb_image.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <memory>

#include "core/color.h"
#include "core/file_io.h"
#include "io/loaders.h"
#include "kestrel/error.h"

namespace kestrel {

namespace {

constexpr uint64_t max_image_file_bytes = uint64_t(1) << 30;

// stb_image 2.27 passes a null buffer to memcpy when a PNG's first IDAT chunk is empty
// (undefined behaviour; found by fuzz_image). Empty IDAT chunks carry no data: they are
// dropped from a copy before stb_image sees the file. Returns false when nothing was dropped.
bool drop_empty_png_idat(const unsigned char* p, size_t n, std::string& out) {
  static const unsigned char signature[8] = {0x89, 'P', 'N', 'G', 0x0D, 0x0A, 0x1A, 0x0A};
  if (n < 8 || std::memcmp(p, signature, 8) != 0) return false;
  bool dropped = false;
  size_t at = 8;
  std::string kept(reinterpret_cast<const char*>(p), 8);
  while (at + 8 <= n) {  // a chunk's length and type are there (its data and CRC may not be)
    const size_t length =
        (size_t(p[at]) << 24) | (size_t(p[at + 1]) << 16) | (size_t(p[at + 2]) << 8) | p[at + 3];
    if (length == 0 && std::memcmp(p + at + 4, "IDAT", 4) == 0) {
      dropped = true;  // also when the file ends inside its CRC: stb_image reads no further
      at += std::min<size_t>(12, n - at);
      continue;
    }
    if (at + 12 > n || length > n - at - 12) break;  // malformed: the rest goes as it is
    kept.append(reinterpret_cast<const char*>(p + at), 12 + length);
    at += 12 + length;
  }
  if (!dropped) return false;
  kept.append(reinterpret_cast<const char*>(p + at), n - at);
  out = std::move(kept);
  return true;
}

// stb_image 2.27 (Debian 12) writes past a Huffman table when a JPEG's DHT segment declares
// more than 256 codes (found by fuzz_image). Its segments are checked here first.
bool jpeg_huffman_tables_ok(const unsigned char* p, size_t n) {
  // stb_image takes any number of 0xFF fill bytes before a marker, the first one included.
  size_t at = 0;
  while (at < n && p[at] == 0xFF) ++at;
  if (at == 0 || at >= n || p[at] != 0xD8) return true;  // not a JPEG: nothing to check
  ++at;
  while (at + 4 <= n) {
    if (p[at] != 0xFF) {  // entropy-coded data: skip to the next marker
      ++at;
      continue;
    }
    const unsigned char marker = p[at + 1];
    if (marker == 0xFF || marker == 0x00 || (marker >= 0xD0 && marker <= 0xD8) || marker == 0x01) {
      at += marker == 0xFF ? 1 : 2;
      continue;
    }
    if (marker == 0xD9) return true;  // end of image
    const size_t length = (size_t(p[at + 2]) << 8) | p[at + 3];
    if (length < 2) return false;
    const size_t end = std::min(n, at + 2 + length);
    if (marker == 0xC4) {  // DHT: tables of (class/id, 16 counts, the codes)
      size_t q = at + 4;
      while (q < end) {
        if (q + 17 > end) return false;
        size_t codes = 0;
        for (int i = 1; i <= 16; ++i) codes += p[q + size_t(i)];
        if (codes > 256 || q + 17 + codes > end) return false;
        q += 17 + codes;
      }
    }
    at = end;
  }
  return true;
}

struct Encoded {
  std::string bytes;
  int width = 0, height = 0;
  bool hdr = false;
  const stbi_uc* data() const { return reinterpret_cast<const stbi_uc*>(bytes.data()); }
  int size() const { return int(bytes.size()); }
};

// The file, checked to be an image stb_image decodes to at most `bytes_per_pixel` x pixels
// within the limits.
Encoded read_image_file(const std::string& path, int bytes_per_pixel) {
  Encoded e;
  e.bytes = read_bounded_file(path, max_image_file_bytes, "image");
  if (std::string cleaned; drop_empty_png_idat(e.data(), e.bytes.size(), cleaned))
    e.bytes = std::move(cleaned);
  int channels = 0;
  if (!jpeg_huffman_tables_ok(e.data(), e.bytes.size()))
    throw Error(
        ErrorCode::parse_error,
        fmt::format("{}: corrupt JPEG (a Huffman table declares more than 256 codes)", path));
  if (!stbi_info_from_memory(e.data(), e.size(), &e.width, &e.height, &channels))
    throw Error(ErrorCode::parse_error, fmt::format("{}: not an image kestrel can decode ({})",
                                                    path, stbi_failure_reason()));
  if (e.width <= 0 || e.height <= 0 || e.width > max_image_side || e.height > max_image_side)
    throw Error(ErrorCode::parse_error,
                fmt::format("{}: image size {}x{} is out of range", path, e.width, e.height));
  check_decoded_size(path, uint64_t(e.width) * uint64_t(e.height) * uint64_t(bytes_per_pixel),
                     e.bytes.size());
  e.hdr = stbi_is_hdr_from_memory(e.data(), e.size()) != 0;
  return e;
}

}  // namespace

bool decode_rgba8(const unsigned char* bytes, size_t size, int& width, int& height,
                  std::vector<unsigned char>& rgba, std::string& problem) {
  if (size > size_t(max_image_file_bytes)) {
    problem = "larger than 1 GiB";
    return false;
  }
  int channels = 0;
  const auto* data = reinterpret_cast<const stbi_uc*>(bytes);
  std::string cleaned;
  if (drop_empty_png_idat(data, size, cleaned)) {
    data = reinterpret_cast<const stbi_uc*>(cleaned.data());
    size = cleaned.size();
  }
  if (!jpeg_huffman_tables_ok(data, size)) {
    problem = "corrupt JPEG (a Huffman table declares more than 256 codes)";
    return false;
  }
  if (!stbi_info_from_memory(data, int(size), &width, &height, &channels)) {
    problem = fmt::format("not an image kestrel can decode ({})", stbi_failure_reason());
    return false;
  }
  try {
    if (width <= 0 || height <= 0 || width > max_image_side || height > max_image_side)
      throw Error(ErrorCode::parse_error,
                  fmt::format("image size {}x{} is out of range", width, height));
    check_decoded_size("image", uint64_t(width) * uint64_t(height) * 4, size);
  } catch (const Error& e) {
    problem = e.what();
    return false;
  }
  std::unique_ptr<stbi_uc, void (*)(void*)> px(
      stbi_load_from_memory(data, int(size), &width, &height, &channels, 4), stbi_image_free);
  if (!px) {
    problem = fmt::format("cannot decode image ({})", stbi_failure_reason());
    return false;
  }
  rgba.assign(px.get(), px.get() + size_t(width) * size_t(height) * 4);
  return true;
}

Texture load_texture(const std::string& path) {
  const Encoded e = read_image_file(path, 4);
  int w = 0, h = 0, channels = 0;
  std::unique_ptr<stbi_uc, void (*)(void*)> pixels(
      stbi_load_from_memory(e.data(), e.size(), &w, &h, &channels, 4), stbi_image_free);
  if (!pixels)
    throw Error(ErrorCode::parse_error,
                fmt::format("{}: cannot decode image ({})", path, stbi_failure_reason()));
  Texture t;
  t.name = path;
  t.width = w;
  t.height = h;
  t.rgba.assign(pixels.get(), pixels.get() + size_t(w) * h * 4);
  return t;
}

FloatImage load_float_image_stb(const std::string& path) {
  const Encoded e = read_image_file(path, 3 * sizeof(float));
  int w = 0, h = 0, n = 0;
  FloatImage image;
  if (e.hdr) {
    std::unique_ptr<float, void (*)(void*)> px(
        stbi_loadf_from_memory(e.data(), e.size(), &w, &h, &n, 3), stbi_image_free);
    if (!px)
      throw Error(ErrorCode::parse_error,
                  fmt::format("{}: cannot decode image ({})", path, stbi_failure_reason()));
    image = FloatImage(w, h, 3);
    std::memcpy(image.pixels.data(), px.get(), image.pixels.size() * sizeof(float));
    return image;
  }
  std::unique_ptr<stbi_uc, void (*)(void*)> px(
      stbi_load_from_memory(e.data(), e.size(), &w, &h, &n, 3), stbi_image_free);
  if (!px)
    throw Error(ErrorCode::parse_error,
                fmt::format("{}: cannot decode image ({})", path, stbi_failure_reason()));
  image = FloatImage(w, h, 3);
  for (size_t i = 0; i < image.pixels.size(); ++i) {
    const float c = px.get()[i] / 255.0f;  // sRGB decode
    image.pixels[i] = srgb_to_linear(c);
  }
  return image;
}

}  // namespace kestrel
