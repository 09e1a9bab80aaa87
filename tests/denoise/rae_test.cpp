// The rae denoiser (Chaitanya et al. 2017's recurrent autoencoder through oneDNN): against
// PyTorch on a committed fixture (three frames: the recurrent states carry), its bound (no
// output above the brightest demodulated sample of the frame) and its state handling (its
// weights file's checks are in denoise_test.cpp).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>

#include "kestrel/denoise.h"
#include "kestrel/io.h"

namespace kestrel {
namespace {

const std::string kFixture = std::string(KESTREL_SOURCE_DIR) + "/tests/data/denoise_rae";

DenoiserOptions rae(bool recurrent = true, bool bf16 = false) {
  DenoiserOptions o;
  o.method = DenoiseMethod::rae;
  o.recurrent = recurrent;
  o.bf16 = bf16;
  return o;
}

struct Frame {
  FloatImage color, albedo, normal, depth, rough, motion;
  DenoiseInput input() const { return {&color, &albedo, &normal, &depth, &rough, &motion}; }
};

Frame fixture_frame(int t) {
  const std::string dir = kFixture + "/frame_" + std::to_string(t) + "/";
  return {read_pfm(dir + "color.pfm"),     read_pfm(dir + "albedo.pfm"),
          read_pfm(dir + "normal.pfm"),    read_pfm(dir + "depth.pfm"),
          read_pfm(dir + "roughness.pfm"), read_pfm(dir + "motion.pfm")};
}

// A noisy frame: fireflies on a textured albedo, some black-albedo pixels, a depth ramp.
Frame noisy_frame(int w, int h, uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u(0.0f, 1.0f);
  Frame f{FloatImage(w, h, 3), FloatImage(w, h, 3), FloatImage(w, h, 3),
          FloatImage(w, h, 1), FloatImage(w, h, 1), FloatImage(w, h, 2)};
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const bool black = (x / 5 + y / 7) % 6 == 0;
      const bool firefly = u(rng) < 0.01f;
      for (int c = 0; c < 3; ++c) {
        f.albedo.at(x, y)[c] = black ? 0.0f : 0.2f + 0.6f * float((x / 3 + c) % 4) / 3.0f;
        f.color.at(x, y)[c] = (firefly ? 400.0f : 2.0f) * u(rng) * (black ? 0.1f : 1.0f);
      }
      f.normal.at(x, y)[2] = 1.0f;
      f.depth.at(x, y)[0] = y < 3 ? 0.0f : 1.0f + 0.05f * float(x);  // a strip of sky
      f.rough.at(x, y)[0] = 0.5f;
    }
  return f;
}

float demodulation(const Frame& f, int x, int y, int c) {
  const float* a = f.albedo.at(x, y);
  return std::max({a[0], a[1], a[2]}) < 0.02f ? 1.0f : std::max(a[c], 0.0f) + 0.01f;
}

double worst_relative(const FloatImage& out, const FloatImage& expected) {
  double worst = 0;
  for (size_t i = 0; i < out.pixels.size(); ++i)
    worst = std::max(worst, std::abs(double(out.pixels[i]) - expected.pixels[i]) /
                                (std::abs(expected.pixels[i]) + 1e-2));
  return worst;
}

TEST(Rae, MatchesPyTorchOnTheFixture) {
  Denoiser d(rae());  // the committed weights
  for (int t = 0; t < 3; ++t) {
    const Frame f = fixture_frame(t);
    const FloatImage expected =
        read_pfm(kFixture + "/frame_" + std::to_string(t) + "/expected.pfm");
    const FloatImage out = d.denoise(f.input());
    ASSERT_EQ(out.width, expected.width);
    ASSERT_EQ(out.height, expected.height);
    EXPECT_LT(worst_relative(out, expected), 1e-4) << "frame " << t;
    double sum = 0;
    for (float v : expected.pixels) sum += v;
    EXPECT_GT(sum, 0.0) << "the fixture must show content";
  }
  EXPECT_GT(d.parameter_count(), 100000u);
}

// bf16 convolutions (where the CPU has them, the default there): PyTorch's fp32 outputs within
// bf16's precision (8 bits of mantissa through 23 layers: ~1 % at worst, not 1e-4).
TEST(Rae, Bf16StaysCloseToPyTorch) {
  Denoiser d(rae(true, true));
  if (!d.uses_bf16()) GTEST_SKIP() << "this CPU has no bf16 convolutions";
  for (int t = 0; t < 3; ++t) {
    const Frame f = fixture_frame(t);
    const FloatImage expected =
        read_pfm(kFixture + "/frame_" + std::to_string(t) + "/expected.pfm");
    const FloatImage out = d.denoise(f.input());
    double se = 0, peak = 0;
    for (size_t i = 0; i < out.pixels.size(); ++i) {
      const double e = out.pixels[i] - expected.pixels[i];
      se += e * e, peak = std::max(peak, double(expected.pixels[i]));
    }
    const double psnr = 10 * std::log10(peak * peak * double(out.pixels.size()) / se);
    EXPECT_GT(psnr, 45.0) << "frame " << t;
    EXPECT_LT(worst_relative(out, expected), 0.05) << "frame " << t;
    EXPECT_GT(worst_relative(out, expected), 1e-5) << "frame " << t << ": bf16 must differ";
  }
}

TEST(Rae, NoOutputAboveTheBrightestDemodulatedSample) {
  for (bool bf16 : {false, true}) {
    Denoiser d(rae(true, bf16));
    for (uint32_t t = 0; t < 3; ++t) {
      const Frame f = noisy_frame(53, 37, 11 + t);  // not a multiple of 16
      const FloatImage out = d.denoise(f.input());
      float top = 0;
      for (int y = 0; y < 37; ++y)
        for (int x = 0; x < 53; ++x)
          for (int c = 0; c < 3; ++c)
            top = std::max(top, f.color.at(x, y)[c] / demodulation(f, x, y, c));
      for (int y = 0; y < 37; ++y)
        for (int x = 0; x < 53; ++x)
          for (int c = 0; c < 3; ++c) {
            const float v = out.at(x, y)[c];
            ASSERT_TRUE(std::isfinite(v) && v >= 0.0f);
            ASSERT_LE(v, top * demodulation(f, x, y, c) * (1 + 1e-5f)) << x << "," << y;
          }
    }
  }
}

TEST(Rae, StateCarriesAndResets) {
  const Frame a = noisy_frame(40, 24, 1), b = noisy_frame(40, 24, 2);
  Denoiser d(rae()), single(rae(false));
  const FloatImage first = d.denoise(a.input());
  const FloatImage second = d.denoise(b.input());
  const FloatImage alone = single.denoise(b.input());
  EXPECT_GT(worst_relative(second, alone), 1e-3) << "the previous frame must change the output";
  EXPECT_EQ(single.denoise(a.input()).pixels, first.pixels) << "frame by frame: no state";
  d.reset();
  EXPECT_EQ(d.denoise(a.input()).pixels, first.pixels) << "reset() starts a new sequence";
  // A size change restarts the sequence too.
  const Frame small = noisy_frame(21, 17, 3);
  Denoiser fresh(rae());
  EXPECT_EQ(d.denoise(small.input()).pixels, fresh.denoise(small.input()).pixels);
}

}  // namespace
}  // namespace kestrel
