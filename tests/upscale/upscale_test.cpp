// The upsamplers: the neural one against PyTorch (committed fixture), its weights file's
// checks, and behaviour against analytic oracles: a constant sequence is a fixed point; a
// static or translating pattern point-sampled at the jitter converges towards its
// pixel-averaged reference, better than the current frame alone, and only with the right
// motion vectors; disoccluded pixels drop their history, the output never leaves the range
// of the samples seen, a lighting change is followed; bad input is an error.
#include "kestrel/upscale.h"

#include <fmt/format.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <random>

#include "kestrel/error.h"
#include "kestrel/io.h"
#include "kestrel/isa.h"
#include "kestrel/render.h"
#include "support/oracles.h"

namespace kestrel {
namespace {

const std::string kFixture = std::string(KESTREL_SOURCE_DIR) + "/tests/data/upscale";

UpscalerOptions options(UpscaleMethod m, int factor, bool bf16 = true) {
  UpscalerOptions o;
  o.method = m, o.factor = factor, o.bf16 = bf16;
  return o;
}

const UpscaleMethod kMethods[] = {UpscaleMethod::neural, UpscaleMethod::taau,
                                  UpscaleMethod::bicubic, UpscaleMethod::bilinear};

// The fixture's frames through the learned TAAU at factor f, each against the training
// framework's output (test::match_images).
std::vector<test::ImageMatch> score_on_fixture(Upscaler& up, int f) {
  std::ifstream meta_file(kFixture + "/fixture.json");
  EXPECT_TRUE(meta_file) << kFixture;
  if (!meta_file) return {};
  const nlohmann::json meta = nlohmann::json::parse(meta_file);
  const int frames = meta["frames"];
  std::vector<test::ImageMatch> scores;
  for (int t = 0; t < frames; ++t) {
    const std::string p = kFixture + "/x" + std::to_string(f) + "_";
    const FloatImage color = read_pfm(p + "color_" + std::to_string(t) + ".pfm");
    FloatImage depth3 = read_pfm(p + "depth_" + std::to_string(t) + ".pfm");
    const FloatImage motion = read_pfm(p + "motion_" + std::to_string(t) + ".pfm");
    const FloatImage expected = read_pfm(p + "out_" + std::to_string(t) + ".pfm");
    FloatImage depth(depth3.width, depth3.height, 1);
    for (size_t i = 0; i < depth.pixels.size(); ++i)
      depth.pixels[i] = depth3.pixels[i * size_t(depth3.channels)];
    UpscaleInput in{&color, &depth, &motion, meta["jitter"][size_t(t)][0],
                    meta["jitter"][size_t(t)][1]};
    const FloatImage out = up.upscale(in);
    scores.push_back(test::match_images(out, expected));
  }
  return scores;
}

TEST(Upscale, NeuralMatchesPyTorchOnTheFixture) {
  // Every ISA this CPU runs, in f32: the convolution kernels and the reconstruction both
  // follow default_isa().
  for (Isa isa : {Isa::sse2, Isa::avx2, Isa::avx512}) {
    if (!isa_supported(isa)) continue;
    SCOPED_TRACE(isa_name(isa));
    const Isa before = default_isa();
    set_default_isa(isa);
    for (int f : {2, 4}) {
      Upscaler up(options(UpscaleMethod::neural, f, false));
      EXPECT_FALSE(up.uses_bf16());
      const std::vector<test::ImageMatch> scores = score_on_fixture(up, f);
      ASSERT_GE(scores.size(), 2u);
      for (size_t t = 0; t < scores.size(); ++t)
        EXPECT_LT(scores[t].worst, 2e-4) << "factor " << f << " frame " << t;
    }
    set_default_isa(before);
  }
}

// bf16 convolutions (the default where the CPU has them): the network's three parameters move
// a little, the output stays close to the training framework's f32 output. Measured 104.5-166
// dB, worst 0.12 % of |expected| + 0.01 (the Zen 5 host, 2026-12-07).
TEST(Upscale, NeuralInBf16StaysCloseToPyTorch) {
  for (int f : {2, 4}) {
    Upscaler up(options(UpscaleMethod::neural, f));
    if (!up.uses_bf16()) GTEST_SKIP() << "this CPU has no bf16 convolutions";
    const std::vector<test::ImageMatch> scores = score_on_fixture(up, f);
    ASSERT_GE(scores.size(), 2u);
    for (size_t t = 0; t < scores.size(); ++t) {
      EXPECT_GT(scores[t].psnr, 80.0) << "factor " << f << " frame " << t;
      EXPECT_LT(scores[t].worst, 0.01) << "factor " << f << " frame " << t;
    }
  }
}

// The reconstruction reads the history by plain loads, shifted loads, permutes of a window or
// gathers, chosen per group of pixels from how far apart their reprojections fall: SSE2 (4
// lanes), AVX2 (8) and AVX-512 (16) group the same pixels differently, so each ISA's frames
// must match SSE2's. The motion mixes a slow smooth pan, depth steps of different motion,
// per-pixel noise, a vertical drift and motion that leaves the image.
TEST(Upscale, EveryIsaReadsTheHistoryAsSse2Does) {
  const int w = 61, h = 37;
  std::mt19937 rng(7);
  std::uniform_real_distribution<float> u(0.0f, 1.0f);
  std::vector<FloatImage> colour, depth, motion;
  for (int t = 0; t < 4; ++t) {
    FloatImage c(w, h, 3), d(w, h, 1), m(w, h, 2);
    for (int j = 0; j < h; ++j)
      for (int i = 0; i < w; ++i) {
        for (int k = 0; k < 3; ++k) c.at(i, j)[k] = u(rng) * (k + 1) * 0.7f;
        const int region = (i / 9 + j / 7) % 4;
        d.at(i, j)[0] = 1.0f + float(region);
        float mx = 0.37f * float(t) + 0.013f * float(i), my = 0.21f - 0.009f * float(j);
        if (region == 1) mx += 0.6f * float(i % 5) - 1.1f;  // columns several pixels apart
        if (region == 2) mx += 3.0f * (u(rng) - 0.5f), my += 2.0f * (u(rng) - 0.5f);
        if (region == 3 && i > w - 12) mx += 20.0f;  // off the image
        m.at(i, j)[0] = mx, m.at(i, j)[1] = my;
      }
    colour.push_back(c), depth.push_back(d), motion.push_back(m);
  }
  const Isa before = default_isa();
  for (UpscaleMethod method : {UpscaleMethod::neural, UpscaleMethod::taau})
    for (int f : {2, 4}) {
      std::vector<FloatImage> reference;
      for (Isa isa : {Isa::sse2, Isa::avx2, Isa::avx512}) {
        if (!isa_supported(isa)) continue;
        SCOPED_TRACE(isa_name(isa));
        set_default_isa(isa);
        Upscaler up(options(method, f, false));  // f32 on every ISA
        for (int t = 0; t < 4; ++t) {
          float jx, jy;
          frame_jitter(uint32_t(t), jx, jy);
          const FloatImage out =
              up.upscale({&colour[size_t(t)], &depth[size_t(t)], &motion[size_t(t)], jx, jy});
          if (isa == Isa::sse2) {
            reference.push_back(out);
            continue;
          }
          double worst = 0;
          for (size_t i = 0; i < out.pixels.size(); ++i)
            worst =
                std::max(worst, std::abs(double(out.pixels[i]) - reference[size_t(t)].pixels[i]) /
                                    (std::abs(double(reference[size_t(t)].pixels[i])) + 1e-2));
          EXPECT_LT(worst, 1e-4) << upscale_method_name(method) << " x" << f << " frame " << t;
        }
      }
    }
  set_default_isa(before);
}

TEST(Upscale, CorruptOrMismatchedWeightsAreErrorsNamingTheFile) {
  const std::string good = std::string(KESTREL_SOURCE_DIR) + "/weights/upscaler.kdw";
  std::ifstream in(good, std::ios::binary);
  std::vector<char> bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  ASSERT_GT(bytes.size(), 100u);
  const std::string dir = testing::TempDir();
  auto write = [&](const std::string& name, const std::vector<char>& b) {
    std::ofstream(dir + name, std::ios::binary).write(b.data(), std::streamsize(b.size()));
    return dir + name;
  };
  std::vector<char> flipped = bytes;
  flipped[bytes.size() / 2] ^= 0x10;
  const std::vector<char> truncated(bytes.begin(),
                                    bytes.begin() + std::ptrdiff_t(bytes.size() / 3));
  const std::string denoiser = std::string(KESTREL_SOURCE_DIR) + "/weights/denoiser.kdw";
  // nsrr's weights: the same magic, an architecture the learned TAAU does not run.
  const std::string nsrr = std::string(KESTREL_SOURCE_DIR) + "/weights/upscaler_nsrr.kdw";
  for (const std::string& path :
       {write("up_flipped.kdw", flipped), write("up_truncated.kdw", truncated), denoiser, nsrr,
        dir + "does_not_exist.kdw"}) {
    UpscalerOptions o;
    o.weights = path;
    try {
      Upscaler up(o);
      FAIL() << "no error for " << path;
    } catch (const Error& e) {
      EXPECT_NE(std::string(e.what()).find(path), std::string::npos) << e.what();
    }
  }
}

// A sharp pattern: a rotated checkerboard with a disc, in output pixels.
float pattern(double x, double y) {
  const double u = 0.8 * x + 0.6 * y, v = -0.6 * x + 0.8 * y;
  const bool check = (int(std::floor(u / 5.0)) + int(std::floor(v / 7.0))) % 2 == 0;
  const double dx = x - 40, dy = y - 30;
  return (check ? 0.8f : 0.1f) + (dx * dx + dy * dy < 200 ? 1.5f : 0.0f);
}

// Frame t of the pattern moving by (vx, vy) output pixels per frame: point-sampled at the
// Halton jitter at low resolution, its motion vectors, and the 8x8-supersampled reference.
struct Moving {
  int w, h, f;
  double vx, vy;
  FloatImage color(int t, float jx, float jy) const {
    FloatImage c(w, h, 3);
    for (int j = 0; j < h; ++j)
      for (int i = 0; i < w; ++i) {
        const float v = pattern(f * (i + jx) - vx * t, f * (j + jy) - vy * t);
        for (int k = 0; k < 3; ++k) c.at(i, j)[k] = v * (0.5f + 0.25f * float(k));
      }
    return c;
  }
  FloatImage motion(bool right) const {
    FloatImage m(w, h, 2);
    for (int p = 0; p < w * h; ++p)
      m.pixels[2 * size_t(p)] = right ? float(-vx / f) : 0.0f,
                   m.pixels[2 * size_t(p) + 1] = right ? float(-vy / f) : 0.0f;
    return m;
  }
  FloatImage reference(int t) const {
    FloatImage r(f * w, f * h, 3);
    for (int Y = 0; Y < f * h; ++Y)
      for (int X = 0; X < f * w; ++X) {
        double s = 0;
        for (int b = 0; b < 8; ++b)
          for (int a = 0; a < 8; ++a)
            s += pattern(X + (a + 0.5) / 8 - vx * t, Y + (b + 0.5) / 8 - vy * t);
        for (int k = 0; k < 3; ++k) r.at(X, Y)[k] = float(s / 64) * (0.5f + 0.25f * float(k));
      }
    return r;
  }
};

double tonemapped_mse(const FloatImage& a, const FloatImage& b, int margin) {
  double s = 0;
  size_t n = 0;
  for (int y = margin; y < a.height - margin; ++y)
    for (int x = margin; x < a.width - margin; ++x)
      for (int k = 0; k < 3; ++k) {
        const double u = a.at(x, y)[k], v = b.at(x, y)[k];
        const double d = u / (1 + u) - v / (1 + v);
        s += d * d, ++n;
      }
  return s / double(n);
}

// Mean error over frames 8..15 of a sequence.
double sequence_error(UpscaleMethod m, const Moving& scene, bool right_motion) {
  Upscaler up(options(m, scene.f));
  const FloatImage depth = [&] {
    FloatImage d(scene.w, scene.h, 1);
    std::fill(d.pixels.begin(), d.pixels.end(), 3.0f);
    return d;
  }();
  const FloatImage motion = scene.motion(right_motion);
  double err = 0;
  for (int t = 0; t < 16; ++t) {
    float jx, jy;
    frame_jitter(uint32_t(t), jx, jy);
    const FloatImage c = scene.color(t, jx, jy);
    const FloatImage out = up.upscale({&c, &depth, &motion, jx, jy});
    if (t >= 8) err += tonemapped_mse(out, scene.reference(t), 2 * scene.f) / 8;
  }
  return err;
}

TEST(Upscale, StaticPatternConvergesBeyondTheCurrentFrame) {
  for (int f : {2, 4}) {
    const Moving scene{96 / f, 64 / f, f, 0, 0};
    const double bicubic = sequence_error(UpscaleMethod::bicubic, scene, true);
    for (UpscaleMethod m : {UpscaleMethod::taau, UpscaleMethod::neural}) {
      const double e = sequence_error(m, scene, true);
      EXPECT_LT(e, 0.9 * bicubic) << upscale_method_name(m) << " x" << f << " " << e
                                  << " vs bicubic " << bicubic;
    }
  }
}

TEST(Upscale, MovingPatternNeedsTheRightMotionVectors) {
  for (int f : {2, 4}) {
    const Moving scene{96 / f, 64 / f, f, 1.5, -0.75};
    const double bicubic = sequence_error(UpscaleMethod::bicubic, scene, true);
    for (UpscaleMethod m : {UpscaleMethod::taau, UpscaleMethod::neural}) {
      const double right = sequence_error(m, scene, true), wrong = sequence_error(m, scene, false);
      EXPECT_LT(right, bicubic) << upscale_method_name(m) << " x" << f;
      EXPECT_LT(right, 0.95 * wrong)
          << upscale_method_name(m) << " x" << f << " right " << right << " wrong " << wrong;
    }
  }
}

TEST(Upscale, ConstantSequenceIsAFixedPoint) {
  for (UpscaleMethod m : kMethods)
    for (int f : {2, 4}) {
      Upscaler up(options(m, f));
      FloatImage c(23, 17, 3), d(23, 17, 1), mo(23, 17, 2);
      for (size_t p = 0; p < c.pixels.size(); ++p) c.pixels[p] = 0.3f + 0.2f * float(p % 3);
      std::fill(d.pixels.begin(), d.pixels.end(), 2.0f);
      for (size_t p = 0; p < mo.pixels.size(); ++p) mo.pixels[p] = (p % 2) ? -0.6f : 1.3f;
      for (int t = 0; t < 4; ++t) {
        float jx, jy;
        frame_jitter(uint32_t(t), jx, jy);
        const FloatImage out = up.upscale({&c, &d, &mo, jx, jy});
        ASSERT_EQ(out.width, 23 * f);
        ASSERT_EQ(out.height, 17 * f);
        for (int y = 0; y < out.height; ++y)
          for (int x = 0; x < out.width; ++x)
            for (int k = 0; k < 3; ++k)
              ASSERT_NEAR(out.at(x, y)[k], 0.3f + 0.2f * float(k), 2e-4)
                  << upscale_method_name(m) << " x" << f;
      }
    }
}

// A grey square (depth 1) moving right by 5 low-resolution pixels a frame over a static
// background of fine stripes (depth 4); the square's grey lies inside the stripes'
// neighbourhood clamp, so only the depth test can tell its history from the background's.
struct Occluder {
  static constexpr int w = 56, h = 32, speed = 5, top = 8, bottom = 24;
  static int left(int t) { return 6 + speed * t; }  // the square spans [left, left + 12)
  static bool inside(int t, float x, float y) {
    return x >= float(left(t)) && x < float(left(t) + 12) && y >= top && y < bottom;
  }
  float brightness = 1.0f;
  void frame(int t, float jx, float jy, FloatImage& c, FloatImage& d, FloatImage& m) const {
    c = FloatImage(w, h, 3), d = FloatImage(w, h, 1), m = FloatImage(w, h, 2);
    for (int j = 0; j < h; ++j)
      for (int i = 0; i < w; ++i) {
        const float x = float(i) + jx, y = float(j) + jy;
        const bool sq = inside(t, x, y);
        const float v = sq ? 0.5f : (int(std::floor(x / 1.5f)) % 2 ? 0.85f : 0.15f);
        for (int k = 0; k < 3; ++k) c.at(i, j)[k] = brightness * v;
        d.at(i, j)[0] = sq ? 1.0f : 4.0f;
        m.at(i, j)[0] = sq ? -float(speed) : 0.0f;
      }
  }
};

// The same frame through an upsampler without history: the current frame's reconstruction.
FloatImage without_history(UpscaleMethod m, int f, const UpscaleInput& in) {
  Upscaler fresh(options(m, f));
  return fresh.upscale(in);
}

TEST(Upscale, DisoccludedPixelsDropTheirHistory) {
  for (UpscaleMethod m : {UpscaleMethod::taau, UpscaleMethod::neural})
    for (int f : {2, 4}) {
      SCOPED_TRACE(fmt::format("{} x{}", upscale_method_name(m), f));
      Upscaler up(options(m, f));
      const Occluder scene;
      for (int t = 0; t < 6; ++t) {
        float jx, jy;
        frame_jitter(uint32_t(t), jx, jy);
        FloatImage c, d, mo;
        scene.frame(t, jx, jy, c, d, mo);
        const UpscaleInput in{&c, &d, &mo, jx, jy};
        const FloatImage out = up.upscale(in);
        if (t < 3) continue;
        const FloatImage cur = without_history(m, f, in);
        // Output pixels whose nearest sample lies where the square was last frame and is not
        // now, a sample clear of where it was (the previous samples around it were all on
        // the square) and two clear of where it is (beyond the motion's 3x3 dilation): the
        // current frame alone. Far from the square's path: the history is kept.
        double disoccluded = 0, kept = 0;
        int n_dis = 0, n_kept = 0;
        for (int Y = 0; Y < out.height; ++Y)
          for (int X = 0; X < out.width; ++X) {
            const int i0 = int(std::floor((X + 0.5) / f - jx + 0.5));
            const int j0 = int(std::floor((Y + 0.5) / f - jy + 0.5));
            const float sx = float(i0) + jx, sy = float(j0) + jy;
            double diff = 0;
            for (int k = 0; k < 3; ++k)
              diff = std::max(diff, double(std::abs(out.at(X, Y)[k] - cur.at(X, Y)[k])));
            if (sx >= float(Occluder::left(t - 1) + 1) && sx < float(Occluder::left(t) - 2) &&
                sy >= Occluder::top + 1 && sy < Occluder::bottom - 2)
              disoccluded = std::max(disoccluded, diff), ++n_dis;
            if (sy < Occluder::top - 3 || sy >= Occluder::bottom + 3) kept += diff, ++n_kept;
          }
        ASSERT_GT(n_dis, 0);
        EXPECT_LT(disoccluded, 1e-4) << "frame " << t;
        EXPECT_GT(kept / n_kept, 1e-4) << "frame " << t;  // the history is used elsewhere
      }
    }
}

// Random black-or-white samples (mostly white: the neighbourhood clamp's upper bound, mu + gamma
// sigma, then lies above the brightest sample) under random sub-pixel motion: every output
// channel stays within the range of the samples seen so far (in the reconstruction's
// y = c / (1 + L(c)) space, where every step is a clamp or a convex combination), because
// Catmull-Rom's overshoot of the history is clamped to the history's own footprint.
TEST(Upscale, OutputStaysWithinTheSamplesSeen) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<float> u01(0.0f, 1.0f);
  auto to_y = [](const float* c, int k) {
    return c[k] / (1.0f + 0.2126f * c[0] + 0.7152f * c[1] + 0.0722f * c[2]);
  };
  for (UpscaleMethod m : {UpscaleMethod::taau, UpscaleMethod::neural})
    for (int f : {2, 4}) {
      SCOPED_TRACE(fmt::format("{} x{}", upscale_method_name(m), f));
      Upscaler up(options(m, f));
      float lo[3] = {1e9f, 1e9f, 1e9f}, hi[3] = {-1e9f, -1e9f, -1e9f};
      double worst = 0;
      for (int t = 0; t < 12; ++t) {
        FloatImage c(24, 16, 3), d(24, 16, 1), mo(24, 16, 2);
        const float mx = 2 * u01(rng) - 1, my = 2 * u01(rng) - 1;
        for (int p = 0; p < 24 * 16; ++p) {
          const float v = u01(rng) < 0.85f ? 4.0f : 0.0f;
          for (int k = 0; k < 3; ++k) c.pixels[3 * size_t(p) + size_t(k)] = v;
          d.pixels[size_t(p)] = 2.0f;
          mo.pixels[2 * size_t(p)] = mx, mo.pixels[2 * size_t(p) + 1] = my;
          for (int k = 0; k < 3; ++k) {
            const float y = to_y(&c.pixels[3 * size_t(p)], k);
            lo[k] = std::min(lo[k], y), hi[k] = std::max(hi[k], y);
          }
        }
        float jx, jy;
        frame_jitter(uint32_t(t), jx, jy);
        const FloatImage out = up.upscale({&c, &d, &mo, jx, jy});
        for (size_t p = 0; p < out.pixels.size() / 3; ++p)
          for (int k = 0; k < 3; ++k) {
            const float y = to_y(&out.pixels[3 * p], k);
            worst = std::max({worst, double(y - hi[k]), double(lo[k] - y)});
          }
      }
      EXPECT_LT(worst, 1e-4);
    }
}

// A static scene whose light drops to a fifth: the next output follows the new frame (the
// neighbourhood clamp rejects the brighter history) instead of carrying the old brightness.
TEST(Upscale, LightingChangeRejectsTheHistory) {
  for (UpscaleMethod m : {UpscaleMethod::taau, UpscaleMethod::neural})
    for (int f : {2, 4}) {
      SCOPED_TRACE(fmt::format("{} x{}", upscale_method_name(m), f));
      Upscaler up(options(m, f));
      Occluder scene;
      for (int t = 0; t < 9; ++t) {
        scene.brightness = t < 8 ? 1.0f : 0.2f;
        float jx, jy;
        frame_jitter(uint32_t(t), jx, jy);
        FloatImage c, d, mo;
        scene.frame(0, jx, jy, c, d, mo);  // the square does not move
        std::fill(mo.pixels.begin(), mo.pixels.end(), 0.0f);
        const UpscaleInput in{&c, &d, &mo, jx, jy};
        const FloatImage out = up.upscale(in);
        if (t < 8) continue;
        const FloatImage cur = without_history(m, f, in);
        double a = 0, b = 0;
        for (size_t i = 0; i < out.pixels.size(); ++i) a += out.pixels[i], b += cur.pixels[i];
        EXPECT_LT(a, 1.3 * b);  // the history alone would be 5x, kept unclamped ~2.6x
        EXPECT_GT(a, 0.9 * b);
      }
    }
}

TEST(Upscale, BadInputIsAnError) {
  EXPECT_THROW(Upscaler(options(UpscaleMethod::taau, 3)), Error);
  Upscaler up(options(UpscaleMethod::taau, 2));
  FloatImage c(8, 8, 3), small(4, 4, 1), two(8, 8, 2), d(8, 8, 1);
  EXPECT_THROW(up.upscale(UpscaleInput{}), Error);
  EXPECT_THROW(up.upscale({&c, &small, nullptr, 0.5f, 0.5f}), Error);
  EXPECT_THROW(up.upscale({&c, &two, nullptr, 0.5f, 0.5f}), Error);
  EXPECT_THROW(up.upscale({&c, &d, &small, 0.5f, 0.5f}), Error);
  EXPECT_THROW(up.upscale({&two, nullptr, nullptr, 0.5f, 0.5f}), Error);
  EXPECT_THROW(up.upscale({&c, &d, nullptr, std::nanf(""), 0.5f}), Error);
  FloatImage empty;
  EXPECT_THROW(up.upscale({&empty, nullptr, nullptr, 0.5f, 0.5f}), Error);
}

TEST(Upscale, NonFiniteInputGivesFiniteOutputAndSizeChangesRestart) {
  for (UpscaleMethod m : kMethods) {
    Upscaler up(options(m, 4));
    for (int size : {9, 9, 12, 12}) {
      FloatImage c(size, size, 3), d(size, size, 1), mo(size, size, 2);
      for (size_t p = 0; p < c.pixels.size(); ++p)
        c.pixels[p] = p % 7 == 0 ? NAN : (p % 11 == 0 ? INFINITY : 0.5f);
      for (size_t p = 0; p < d.pixels.size(); ++p) d.pixels[p] = p % 5 == 0 ? NAN : 1.0f;
      for (size_t p = 0; p < mo.pixels.size(); ++p) mo.pixels[p] = p % 3 == 0 ? INFINITY : -1e30f;
      const FloatImage out = up.upscale({&c, &d, &mo, 0.3f, 0.7f});
      ASSERT_EQ(out.width, 4 * size);
      for (float v : out.pixels) ASSERT_TRUE(std::isfinite(v) && v >= 0) << upscale_method_name(m);
    }
  }
}

}  // namespace
}  // namespace kestrel
