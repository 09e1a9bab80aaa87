// Frame outputs: AOV names and channels, the multi-layer EXR, one PFM per AOV, and the
// documented tone map (exposure, ACES filmic fit, sRGB).
#include <fmt/format.h>

#include <emmintrin.h>  // SSE2: every x86-64

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <filesystem>

#include "core/file_io.h"
#include "core/parallel.h"
#include "kestrel/error.h"
#include "kestrel/render.h"

namespace kestrel {

const char* aov_name(Aov aov) {
  static const char* names[aov_count] = {"color",     "albedo", "normal", "depth",
                                         "roughness", "motion", "spp",    "variance"};
  return names[int(aov)];
}

int aov_channels(Aov aov) {
  static const int channels[aov_count] = {3, 3, 3, 1, 1, 2, 1, 1};
  return channels[int(aov)];
}

std::vector<ImageLayer> Frame::layers() const {
  std::vector<ImageLayer> out;
  for (int a = 0; a < aov_count; ++a) {
    const Aov aov = Aov(a);
    std::vector<std::string> names;
    switch (aov) {
      case Aov::color:
      case Aov::albedo:
        names = {"R", "G", "B"};
        break;
      case Aov::normal:
        names = {"X", "Y", "Z"};
        break;
      case Aov::depth:
        names = {"Z"};
        break;
      case Aov::motion:
        names = {"X", "Y"};
        break;
      default:
        names = {"Y"};
        break;
    }
    out.push_back(ImageLayer{aov_name(aov), names, this->aov[a]});
  }
  return out;
}

void write_frame_exr(const std::string& path, const Frame& frame) {
  const std::vector<ImageLayer> layers = frame.layers();
  write_exr(path, layers);
}

void write_frame_pfms(const std::string& dir, const Frame& frame) {
  make_directories(dir);
  for (int a = 0; a < aov_count; ++a)
    write_pfm((std::filesystem::path(dir) / (std::string(aov_name(Aov(a))) + ".pfm")).string(),
              frame.aov[a]);
}

namespace {

// ACES filmic fit (Narkowicz 2015) of linear x, into [0, 1]; NaN and negatives to 0.
inline float aces_fit(float x) {
  x = x > 0 ? std::min(x, 1e6f) : 0.0f;
  return std::clamp((x * (2.51f * x + 0.03f)) / (x * (2.43f * x + 0.59f) + 0.14f), 0.0f, 1.0f);
}

inline float srgb_oetf(float y) {
  return y <= 0.0031308f ? 12.92f * y : 1.055f * std::pow(y, 1.0f / 2.4f) - 0.055f;
}

// The table index of aces_fit(x * scale) for n values, four at a time with SSE2: the same
// operations in the same order (MAXPS / MINPS keep aces_fit's NaN and range handling:
// max(NaN, 0) is 0), so the same bits as the scalar fit.
void aces_indices(const float* in, size_t n, float scale, uint32_t* idx) {
  const __m128 sc = _mm_set1_ps(scale), zero = _mm_setzero_ps(), big = _mm_set1_ps(1e6f),
               one = _mm_set1_ps(1.0f), a = _mm_set1_ps(2.51f), b = _mm_set1_ps(0.03f),
               c = _mm_set1_ps(2.43f), d = _mm_set1_ps(0.59f), e = _mm_set1_ps(0.14f),
               steps = _mm_set1_ps(65535.0f), half = _mm_set1_ps(0.5f);
  size_t k = 0;
  for (; k + 4 <= n; k += 4) {
    const __m128 x = _mm_min_ps(_mm_max_ps(_mm_mul_ps(_mm_loadu_ps(in + k), sc), zero), big);
    const __m128 num = _mm_mul_ps(x, _mm_add_ps(_mm_mul_ps(a, x), b));
    const __m128 den = _mm_add_ps(_mm_mul_ps(x, _mm_add_ps(_mm_mul_ps(c, x), d)), e);
    const __m128 y = _mm_max_ps(_mm_min_ps(_mm_div_ps(num, den), one), zero);
    _mm_storeu_si128(reinterpret_cast<__m128i*>(idx + k),
                     _mm_cvttps_epi32(_mm_add_ps(_mm_mul_ps(y, steps), half)));
  }
  for (; k < n; ++k) idx[k] = uint32_t(aces_fit(in[k] * scale) * 65535.0f + 0.5f);
}

}  // namespace

float tonemap_aces_srgb(float x) {
  return srgb_oetf(aces_fit(x));
}

std::vector<uint8_t> tonemap_srgb8(const FloatImage& color, float exposure_stops) {
  std::vector<uint8_t> out;
  tonemap_srgb8(color, exposure_stops, out);
  return out;
}

void tonemap_srgb8(const FloatImage& color, float exposure_stops, std::vector<uint8_t>& out) {
  if (color.channels < 3)
    throw Error(ErrorCode::invalid_argument, "tone map: the image needs 3 channels");
  // The sRGB OETF of the ACES output y in [0, 1], quantised to 8 bits, from a table of y
  // (2^16 steps: under 0.06 of a code value from the exact curve where it is steepest).
  static const std::vector<uint8_t> oetf = [] {
    std::vector<uint8_t> t(65536);
    for (size_t i = 0; i < t.size(); ++i) {
      const float y = float(i) / 65535.0f;
      t[i] = uint8_t(std::lround(255.0f * srgb_oetf(y)));
    }
    return t;
  }();
  const float scale = std::exp2(exposure_stops);
  const size_t n = size_t(color.width) * size_t(color.height), ch = size_t(color.channels);
  out.resize(n * 3);  // every byte written
  parallel_for(0, n, 16384, [&](size_t b, size_t e) {
    constexpr size_t block = 256;  // pixels
    uint32_t idx[3 * block];
    float rgb[3 * block];
    for (size_t p0 = b; p0 < e; p0 += block) {
      const size_t m = std::min(block, e - p0);
      const float* in = &color.pixels[p0 * ch];
      if (ch != 3) {  // the colour channels alone
        for (size_t p = 0; p < m; ++p)
          for (size_t c = 0; c < 3; ++c) rgb[3 * p + c] = color.pixels[(p0 + p) * ch + c];
        in = rgb;
      }
      aces_indices(in, 3 * m, scale, idx);
      for (size_t k = 0; k < 3 * m; ++k) out[3 * p0 + k] = oetf[idx[k]];
    }
  });
}

}  // namespace kestrel
