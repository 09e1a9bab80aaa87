// The real-time SVGF (vectorised per ISA, svgf_kernels.inl) against its plain scalar
// definition (SvgfReference: std::exp, branches, skipped border taps) over a synthetic
// sequence that exercises every case: black and coloured albedo, pixels without normals,
// depth edges, sub-pixel motion, motion out of the image, disocclusions, short and long
// histories; on every ISA this CPU runs. Also: the Denoiser's svgf method is this function.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>
#include <string>
#include <utility>

#include "denoise/svgf.h"
#include "kestrel/denoise.h"
#include "kestrel/isa.h"

namespace kestrel::denoise {
namespace {

// Frame t of a scene: a slanted floor (depth gradient), a box in front that moves right by
// 1.5 px per frame (depth and normal edges, disocclusion), a black-albedo stripe, a strip with no
// normal (sky), noisy colour with fireflies; motion vectors point to the previous frame.
// With `zoom`, the camera also zooms below row 45 (motion growing with x, and below row 53
// with y as well): neighbouring pixels' history taps differ, within a row or across two.
Planes frame(int W, int H, int t, std::mt19937& rng, bool zoom = false) {
  Planes g(W, H, 13);
  std::uniform_real_distribution<float> u(0.0f, 1.0f);
  const float box_x0 = 10.0f + 1.5f * float(t);
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x) {
      const size_t p = size_t(y) * size_t(W) + size_t(x);
      const bool sky = y < 4;
      const bool box = float(x) >= box_x0 && float(x) < box_x0 + 20 && y > 15 && y < 40;
      const bool black = x > 70 && x < 76;
      float albedo[3] = {0.8f, 0.5f, 0.2f};
      if (box) albedo[0] = 0.1f, albedo[1] = 0.6f, albedo[2] = 0.9f;
      if (black) albedo[0] = albedo[1] = albedo[2] = 0.005f;
      const float light = box ? 2.0f : 0.5f + 0.01f * float(x);
      for (int c = 0; c < 3; ++c) {
        float v = light * albedo[c] * 2.0f * u(rng);
        if (u(rng) < 0.01f) v *= 50.0f;  // fireflies
        g.ch(c)[p] = sky ? 1.5f : v;
        g.ch(3 + c)[p] = sky ? 1.0f : albedo[c];
      }
      // The box's upper half faces like the floor and is 15 % nearer (between the history
      // test's 10 % and a wrong 20 %: only the depth test tells them apart); its lower half
      // is at the floor's depth but tilted (n.n' = 0.76: only the normal test does).
      const bool facing = box && y >= 28;
      const float nx = facing ? 0.0f : 0.3f, ny = facing ? 0.8f : 0.954f, nz = facing ? 0.6f : 0.0f;
      g.ch(6)[p] = sky ? 0.0f : nx, g.ch(7)[p] = sky ? 0.0f : ny, g.ch(8)[p] = sky ? 0.0f : nz;
      g.ch(9)[p] = (sky ? 1e4f : 5.0f + 0.2f * float(y)) * (box && !facing ? 0.85f : 1.0f);
      g.ch(10)[p] = 0.5f;
      // The box moved +1.5 px: its pixels came from 1.5 px to the left; the floor is still
      // but the camera pans 0.3 px down (sub-pixel), and the last columns look outside.
      const bool zx = zoom && y >= 45, zy = zoom && y >= 53;
      g.ch(11)[p] = box ? -1.5f : (x > W - 3 ? 2.5f : zx ? -0.04f * float(x) : 0.0f);
      g.ch(12)[p] = box ? 0.0f : zy ? -0.3f - 0.01f * float(x) : -0.3f;
    }
  return g;
}

// Over the first `channels` channels of a and b (same size).
double max_rel_diff(const Planes& a, const Planes& b, int channels) {
  double worst = 0;
  const size_t n = size_t(b.width) * size_t(b.height);
  for (int c = 0; c < channels; ++c)
    for (size_t i = 0; i < n; ++i) {
      const double d = std::abs(double(a.ch(c)[i]) - double(b.ch(c)[i])) /
                       std::max(std::abs(double(b.ch(c)[i])), 1e-2);
      worst = std::max(worst, d);
    }
  return worst;
}

TEST(Svgf, EveryIsaMatchesTheScalarDefinition) {
  // 97: not a multiple of any vector width (edge vectors, an overlapping last vector); 3: a
  // row narrower than every vector (pixel by pixel); 19: one AVX-512 vector and three columns
  // (its edge vectors overlap each other).
  for (auto [W, H] : {std::pair{97, 61}, {3, 11}, {19, 23}})
    for (Isa isa : {Isa::sse2, Isa::avx2, Isa::avx512}) {
      if (!isa_supported(isa)) continue;
      SCOPED_TRACE(isa_name(isa));
      SCOPED_TRACE(W);
      const Isa before = default_isa();
      set_default_isa(isa);
      std::mt19937 rng(7);
      Svgf fast;
      SvgfReference ref;
      for (int t = 0; t < 7; ++t) {
        SCOPED_TRACE(t);
        const Planes g = frame(W, H, t, rng);
        const Planes& a = fast.run(g);
        const Planes b = ref.run(g);
        ASSERT_EQ(a.width, W);
        ASSERT_EQ(a.height, H);
        // The fast form differs by its exp (a polynomial in base 2, 8e-8), its reciprocals (one
        // per pixel for the luminance stop, four for the depth stop's slopes) and its summation
        // order (measured: 5.6e-7 to 3.4e-6 on SSE2); with AVX2 / AVX-512 also by fused
        // multiply-adds, which the luminance edge stop (|l - l'| / sqrt(variance), steep where the
        // variance is small) amplifies over the passes (measured: 4e-4 to 1.1e-2). A wrong tap,
        // slope, border, gather or history test shows as 0.1 and more on some frame (on AVX2: a
        // swapped depth slope 0.17-0.27; a border pixel's blur not renormalised 0.03-0.14; the
        // reprojection's gathers one pixel off 0.09-0.27).
        EXPECT_LT(max_rel_diff(a, b, 3), isa == Isa::sse2 ? 1e-5 : 2e-2);
      }
      set_default_isa(before);
    }
}

// AVX-512 reprojects a moving camera's history by permutes within two loaded vectors where
// AVX2 gathers; the two are otherwise the same operations (fused multiply-adds alike), so they
// must agree to rounding. (Against the scalar definition the fused multiply-adds alone differ
// by up to 6e-2 on this sequence; a permute one pixel off shows here as 1e-1 and more.)
TEST(Svgf, Avx512ReprojectionMatchesAvx2) {
  if (!isa_supported(Isa::avx512) || !isa_supported(Isa::avx2)) GTEST_SKIP() << "no AVX-512";
  const int W = 97, H = 61;
  const Isa before = default_isa();
  Svgf fast[2];
  std::mt19937 rng(11);
  for (int t = 0; t < 7; ++t) {
    SCOPED_TRACE(t);
    const Planes g = frame(W, H, t, rng, /*zoom=*/true);
    Planes out[2];
    for (int k = 0; k < 2; ++k) {
      set_default_isa(k == 0 ? Isa::avx2 : Isa::avx512);
      out[k] = fast[k].run(g);
    }
    EXPECT_LT(max_rel_diff(out[1], out[0], 3), 1e-5);
  }
  set_default_isa(before);
}

// A frame's planes as the public API's images.
struct Images {
  FloatImage color, albedo, normal, depth, rough, motion;
  explicit Images(const Planes& g)
      : color(g.width, g.height, 3),
        albedo(g.width, g.height, 3),
        normal(g.width, g.height, 3),
        depth(g.width, g.height, 1),
        rough(g.width, g.height, 1),
        motion(g.width, g.height, 2) {
    for (int y = 0; y < g.height; ++y)
      for (int x = 0; x < g.width; ++x) {
        const size_t p = size_t(y) * size_t(g.width) + size_t(x);
        for (int c = 0; c < 3; ++c) {
          color.at(x, y)[c] = g.ch(c)[p];
          albedo.at(x, y)[c] = g.ch(3 + c)[p];
          normal.at(x, y)[c] = g.ch(6 + c)[p];
        }
        depth.at(x, y)[0] = g.ch(9)[p];
        rough.at(x, y)[0] = g.ch(10)[p];
        motion.at(x, y)[0] = g.ch(11)[p], motion.at(x, y)[1] = g.ch(12)[p];
      }
  }
  DenoiseInput input() const { return {&color, &albedo, &normal, &depth, &rough, &motion}; }
};

// The Denoiser's svgf method is Svgf::run frame by frame, bit for bit: over a sequence (its
// history kept as the previous frame's own input planes) and across size changes, which
// restart it.
TEST(Svgf, DenoiserMethodIsTheRealTimeForm) {
  std::mt19937 rng(3);
  DenoiserOptions o;
  o.method = DenoiseMethod::svgf;
  Denoiser d(o);
  Svgf fast;
  FloatImage out;  // reused, as a frame loop does
  const std::pair<int, int> sizes[] = {{40, 24}, {40, 24}, {40, 24}, {33, 20},
                                       {33, 20}, {40, 24}, {40, 24}};
  for (int t = 0; t < 7; ++t) {
    SCOPED_TRACE(t);
    const auto [W, H] = sizes[t];
    const Planes g = frame(W, H, t, rng);
    d.denoise(Images(g).input(), out);
    const Planes& a = fast.run(g);
    ASSERT_EQ(out.width, W);
    ASSERT_EQ(out.height, H);
    for (int y = 0; y < H; ++y)
      for (int x = 0; x < W; ++x)
        for (int c = 0; c < 3; ++c)
          ASSERT_EQ(out.at(x, y)[c], a.ch(c)[size_t(y) * size_t(W) + size_t(x)]);
  }
}

// The layout the filters' speed depends on (Planes in neural.h): at 1280 x 720 a plane is
// exactly 900 pages, and channels laid end to end put the same pixel of every channel in one
// set of a 64-set L1 cache (the neural filter measured 2-2.5x slower). Sets are counted from
// the start of the buffer (the allocation's own alignment is the same for all channels).
TEST(Planes, ChannelsAndObjectsFallInDifferentCacheSets) {
  for (const auto& [w, h] :
       {std::pair{1280, 720}, std::pair{1920, 1080}, std::pair{640, 360}, std::pair{48, 32}}) {
    SCOPED_TRACE(std::to_string(w) + "x" + std::to_string(h));
    const Planes a(w, h, 13), b(w, h, 13);
    auto set = [](const Planes& p, int c) {
      return ((size_t(p.ch(c) - p.data.data()) * sizeof(float)) / 64) % 64;
    };
    for (int c = 0; c < 13; ++c) {
      EXPECT_EQ(size_t(a.ch(c) - a.data.data()) % 16, 0u) << "channel " << c << " off a line";
      EXPECT_GE(a.data.size(), size_t(a.ch(c) - a.data.data()) + size_t(w) * size_t(h));
      for (int d = 0; d < c; ++d) {
        const size_t gap = (set(a, c) + 64 - set(a, d)) % 64;
        EXPECT_GE(std::min(gap, 64 - gap), 3u) << "channels " << d << " and " << c;
      }
    }
    EXPECT_NE(set(a, 0), set(b, 0)) << "two Planes start in the same set";
    // Writing every channel stays inside the buffer and leaves the others alone.
    Planes p(w, h, 3);
    for (int c = 0; c < 3; ++c) std::fill(p.ch(c), p.ch(c) + size_t(w) * size_t(h), float(c + 1));
    for (int c = 0; c < 3; ++c) {
      EXPECT_EQ(p.ch(c)[0], float(c + 1));
      EXPECT_EQ(p.ch(c)[size_t(w) * size_t(h) - 1], float(c + 1));
    }
  }
}

}  // namespace
}  // namespace kestrel::denoise
