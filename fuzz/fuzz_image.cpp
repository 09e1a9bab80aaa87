// 8-bit and HDR images through stb_image (PNG, JPEG, Radiance .hdr, ...): as an environment
// (float RGB) and as a texture (RGBA8).
#include "fuzz_driver.h"
#include "io/loaders.h"
#include "kestrel/io.h"

const char* const kestrel::fuzz::input_name = "fuzz.png";

void kestrel::fuzz::fuzz_one(const std::string& path, const std::string&) {
  try {
    (void)read_float_image(path);
  } catch (const Error&) {
  }
  (void)load_texture(path);
}
