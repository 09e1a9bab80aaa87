// Network weights (.kdw): as the denoiser's and as the upsampler's.
#include "fuzz_driver.h"
#include "kestrel/denoise.h"
#include "kestrel/upscale.h"

const char* const kestrel::fuzz::input_name = "fuzz.kdw";

void kestrel::fuzz::fuzz_one(const std::string& path, const std::string&) {
  try {
    DenoiserOptions d;
    d.weights = path;
    Denoiser denoiser(d);
  } catch (const Error&) {
  }
  UpscalerOptions u;
  u.weights = path;
  Upscaler upscaler(u);
}
