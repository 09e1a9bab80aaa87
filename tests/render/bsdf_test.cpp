// The BSDF against its own pdf and against analytic facts: chi-square tests of sampling
// (sample histogram vs the pdf integrated per bin), eval / pdf / sample agreement,
// reciprocity, the GGX "weak white furnace" (D and G1 normalised) and energy bounds.
#include <gtest/gtest.h>

#include <fmt/format.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <limits>
#include <random>
#include <vector>

#include "render/bsdf_sampling.h"
#include "render/fast_math.h"
#include "support/oracles.h"

namespace kestrel::render {
namespace {

struct Case {
  const char* name;
  BsdfParams p;
};

std::vector<Case> cases() {
  auto make = [](Vec3 base, float metallic, float roughness, float specular) {
    BsdfParams p;
    p.base = base, p.metallic = metallic, p.alpha = std::max(roughness * roughness, min_alpha),
    p.specular = specular;
    return p;
  };
  return {{"lambertian", make({0.7f, 0.5f, 0.3f}, 0, 1, 0)},
          {"coated_rough", make({0.6f, 0.6f, 0.6f}, 0, 0.7f, 1)},
          {"coated_glossy", make({0.2f, 0.4f, 0.8f}, 0, 0.35f, 1)},
          {"conductor_rough", make({0.95f, 0.64f, 0.54f}, 1, 0.6f, 0)},
          {"conductor_glossy", make({0.9f, 0.9f, 0.9f}, 1, 0.3f, 0)},
          {"mixed", make({0.5f, 0.8f, 0.3f}, 0.5f, 0.45f, 0.5f)}};
}

class BsdfCase : public ::testing::TestWithParam<std::tuple<int, float>> {};

TEST_P(BsdfCase, SamplingMatchesPdfChiSquare) {
  const auto [index, cos_o] = GetParam();
  const Case c = cases()[size_t(index)];
  const Vec3 wo{std::sqrt(1 - cos_o * cos_o), 0, cos_o};
  const SamplingCheck r = expect_sampling_matches_pdf(c.p, wo, false, 10, 1234u + unsigned(index),
                                                      fmt::format("{} cos_o {}", c.name, cos_o));
  EXPECT_LE(r.total, 1.001) << c.name << ": the pdf integrates to more than 1";
}

TEST_P(BsdfCase, EvalPdfAndSampleAgree) {
  const auto [index, cos_o] = GetParam();
  const Case c = cases()[size_t(index)];
  const Vec3 wo{std::sqrt(1 - cos_o * cos_o), 0, cos_o};
  std::mt19937 gen(99);
  std::uniform_real_distribution<float> u(0.0f, 0x1.fffffep-1f);
  for (int s = 0; s < 2000; ++s) {
    BsdfSample bs;
    if (!bsdf_sample(c.p, wo, u(gen), u(gen), u(gen), bs)) continue;
    const float pdf = bsdf_pdf(c.p, wo, bs.wi);
    const Vec3 f = bsdf_eval(c.p, wo, bs.wi);
    ASSERT_NEAR(bs.pdf, pdf, 1e-5f * pdf);
    for (int k = 0; k < 3; ++k) ASSERT_NEAR(bs.weight[k], f[k] / pdf, 1e-4f * (1 + f[k] / pdf));
    // Reciprocity: f(wo, wi) = f(wi, wo) (eval carries cos(wi)).
    const Vec3 fr = bsdf_eval(c.p, bs.wi, wo);
    for (int k = 0; k < 3; ++k)
      ASSERT_NEAR(f[k] / bs.wi.z, fr[k] / wo.z, 2e-4f * (1 + f[k] / bs.wi.z));
  }
  // Below the surface: nothing.
  EXPECT_EQ(bsdf_pdf(c.p, wo, Vec3{0, 0.6f, -0.8f}), 0.0f);
  EXPECT_EQ(luminance(bsdf_eval(c.p, wo, Vec3{0, 0.6f, -0.8f})), 0.0f);
}

TEST_P(BsdfCase, ReflectsNoMoreThanItReceives) {
  const auto [index, cos_o] = GetParam();
  const Case c = cases()[size_t(index)];
  const Vec3 wo{std::sqrt(1 - cos_o * cos_o), 0, cos_o};
  // Directional albedo by quadrature: at most 1 (+ quadrature error) in every channel.
  constexpr int nt = 256, np = 256;
  Vec3 albedo{0, 0, 0};
  for (int i = 0; i < nt; ++i)
    for (int j = 0; j < np; ++j) {
      const float t = (i + 0.5f) * (pi / 2) / nt, ph = (j + 0.5f) * 2 * pi / np;
      albedo =
          albedo + bsdf_eval(c.p, wo, dir(t, ph)) * (std::sin(t) * (pi / 2 / nt) * (2 * pi / np));
    }
  for (int k = 0; k < 3; ++k) EXPECT_LE(albedo[k], 1.01f) << c.name;
}

INSTANTIATE_TEST_SUITE_P(All, BsdfCase,
                         ::testing::Combine(::testing::Range(0, 6),
                                            ::testing::Values(0.9f, 0.5f, 0.15f)));

TEST(Bsdf, LambertianIsBaseOverPi) {
  BsdfParams p;
  p.base = {0.5f, 0.25f, 1.0f}, p.metallic = 0, p.specular = 0, p.alpha = 1;
  const Vec3 wo = normalize(Vec3{0.3f, 0.1f, 0.9f}), wi = normalize(Vec3{-0.5f, 0.2f, 0.4f});
  const Vec3 f = bsdf_eval(p, wo, wi);
  for (int k = 0; k < 3; ++k) EXPECT_NEAR(f[k], p.base[k] / pi * wi.z, 1e-6f);
  EXPECT_NEAR(bsdf_pdf(p, wo, wi), wi.z / pi, 1e-6f);
}

TEST(Bsdf, GgxWeakWhiteFurnace) {
  // Heitz 2014: the integral of D(h) G1(wo) / (4 |wo.z|) over all wi (reflected through h)
  // is 1 for any wo and alpha: checks D and G1 are normalised together. In h-space this is
  // the visible-normal distribution's integral: G1(wo) max(0, wo.h) D(h) / wo.z over h.
  for (float alpha : {0.05f, 0.2f, 0.5f, 1.0f})
    for (float cos_o : {0.95f, 0.6f, 0.2f}) {
      const Vec3 wo{std::sqrt(1 - cos_o * cos_o), 0, cos_o};
      constexpr int nt = 2048, np = 512;
      double sum = 0;
      for (int i = 0; i < nt; ++i) {
        // Dense near the pole for small alpha: theta = (pi/2) * s^2.
        const double s0 = double(i) / nt, s1 = double(i + 1) / nt;
        const double t0 = (pi / 2) * s0 * s0, t1 = (pi / 2) * s1 * s1, t = 0.5 * (t0 + t1);
        for (int j = 0; j < np; ++j) {
          const double ph = (j + 0.5) * 2 * pi / np;
          const Vec3 h = dir(float(t), float(ph));
          const double dh = std::max(0.0f, dot(wo, h));
          sum += ggx_g1(alpha, wo) * dh * ggx_d(alpha, h) / wo.z * std::sin(t) * (t1 - t0) *
                 (2 * pi / np);
        }
      }
      EXPECT_NEAR(sum, 1.0, 0.005) << "alpha " << alpha << " cos_o " << cos_o;
    }
}

// The shading loop's trigonometry (render/fast_math.h) against double precision: every
// quadrant boundary and a dense sweep, including u outside [0, 1) and negative zero.
TEST(FastMath, SinCosOfTurnsMatchDoublePrecision) {
  double worst = 0;
  for (int i = -40000; i <= 40000; ++i) {
    const float u = float(i) / 16384.0f;  // quarter turns land exactly on the grid
    float s, c;
    sincos_2pi(u, s, c);
    const double a = 2 * 3.14159265358979323846 * double(u);
    worst = std::max({worst, std::fabs(s - std::sin(a)), std::fabs(c - std::cos(a))});
  }
  EXPECT_LT(worst, 3e-7);
  for (float u : {0.0f, -0.0f, 0.25f, 0.5f, 0.75f, 1.0f, -0.25f}) {
    float s, c;
    sincos_2pi(u, s, c);
    EXPECT_NEAR(s * s + c * c, 1.0f, 1e-6f) << u;
  }
  float s, c;
  sincos_2pi(0.25f, s, c);
  EXPECT_EQ(s, 1.0f);
  EXPECT_EQ(c, 0.0f);
}

// Floats where rounding to an integer goes wrong: ties, the sign of zero, the largest
// non-integers, integers beyond 2^23, denormals, infinities; then random ones and quarters.
std::vector<float> rounding_cases() {
  std::vector<float> xs = {0.0f,
                           0.5f,
                           1.0f,
                           1.5f,
                           2.5f,
                           0.49999997f,
                           0.99999994f,
                           0x1p23f - 0.5f,
                           0x1p23f,
                           0x1p23f + 1,
                           1e30f,
                           std::numeric_limits<float>::infinity(),
                           std::numeric_limits<float>::denorm_min(),
                           1e-40f};
  for (size_t i = 0, n = xs.size(); i < n; ++i) xs.push_back(-xs[i]);
  std::mt19937 rng(5);
  std::uniform_real_distribution<float> wide(-1e7f, 1e7f), narrow(-4.0f, 4.0f);
  for (int i = 0; i < 100000; ++i) xs.push_back(wide(rng)), xs.push_back(narrow(rng));
  for (int i = -4096; i <= 4096; ++i) xs.push_back(float(i) * 0.25f);  // halves and quarters
  return xs;
}

// round_even is std::nearbyint (default rounding mode) bit for bit, floor_exact std::floor:
// on rounding_cases() and NaN.
TEST(FastMath, RoundEvenIsNearbyintAndFloorExactIsFloor) {
  const auto bits = [](float x) { return std::bit_cast<uint32_t>(x); };
  for (const float x : rounding_cases()) {
    EXPECT_EQ(bits(round_even(x)), bits(std::nearbyint(x))) << x;
    EXPECT_EQ(bits(floor_exact(x)), bits(std::floor(x))) << x;
  }
  EXPECT_TRUE(std::isnan(round_even(std::numeric_limits<float>::quiet_NaN())));
  EXPECT_TRUE(std::isnan(floor_exact(std::numeric_limits<float>::quiet_NaN())));
}

// One shading point serves a light sample and a BSDF sample (BsdfAt keeps what depends on wo):
// its value and pdf for many directions against the formulas of the header comment evaluated
// in double precision, term by term, and the value the same bits with or without the pdf.
TEST(Bsdf, OnePointServesManyDirectionsAsTheFormulasSay) {
  const auto schlick = [](double c) { return std::pow(std::clamp(1.0 - c, 0.0, 1.0), 5.0); };
  const auto lambda = [](double a, double z) {
    return 0.5 * (-1.0 + std::sqrt(1.0 + a * a * std::max(0.0, 1.0 - z * z) / (z * z)));
  };
  const auto d_ggx = [](double a, double z) {
    const double t = z * z * (a * a - 1.0) + 1.0;
    return a * a / (M_PI * t * t);
  };
  std::mt19937 rng(11);
  std::uniform_real_distribution<float> u(0.0f, 1.0f);
  double worst_f = 0, worst_pdf = 0;
  for (const Case& c : cases())
    for (const float cos_o : {0.05f, 0.3f, 0.7f, 1.0f, -0.4f}) {
      const Vec3 wo = normalize(Vec3{std::sqrt(std::max(0.0f, 1 - cos_o * cos_o)), 0.2f, cos_o});
      const BsdfAt at(c.p, wo);
      const double a = c.p.alpha, s = c.p.specular, m = c.p.metallic;
      for (int i = 0; i < 2000; ++i) {
        const Vec3 wi = normalize(Vec3{2 * u(rng) - 1, 2 * u(rng) - 1, 2 * u(rng) - 1.2f});
        Vec3 f, f_alone;
        float pdf;
        at.eval(wi, f, &pdf);
        at.eval(wi, f_alone, nullptr);
        ASSERT_EQ(std::bit_cast<uint32_t>(f.y), std::bit_cast<uint32_t>(f_alone.y));
        ASSERT_EQ(pdf, bsdf_pdf(c.p, wo, wi));
        if (wo.z <= 0 || wi.z <= 0) {
          EXPECT_EQ(luminance(f), 0.0f);
          EXPECT_EQ(pdf, 0.0f);
          continue;
        }
        const double ox = wo.x, oy = wo.y, oz = wo.z, ix = wi.x, iy = wi.y, iz = wi.z;
        const double hx = ox + ix, hy = oy + iy, hz = oz + iz,
                     hl = std::sqrt(hx * hx + hy * hy + hz * hz);
        const double hdi = (ix * hx + iy * hy + iz * hz) / hl, hzn = hz / hl;
        const double fd =
            (1 - s * (0.04 + 0.96 * schlick(iz))) * (1 - s * (0.04 + 0.96 * schlick(oz)));
        const double w = schlick(hdi), fr_d = s * (0.04 + 0.96 * w) * (1 - m);
        const double fr = fr_d + (c.p.base.y + (1 - c.p.base.y) * w) * m;
        const double glossy = (m > 0 || s > 0) ? 1.0 : 0.0;
        const double expect_f =
            c.p.base.y * (1 - m) * fd / M_PI * iz +
            glossy * fr * d_ggx(a, hzn) / (1 + lambda(a, oz) + lambda(a, iz)) / (4 * oz);
        const double ps = at.ps;
        EXPECT_FLOAT_EQ(float(ps), specular_probability(c.p, wo));
        const double expect_pdf =
            (1 - ps) * iz / M_PI + ps * d_ggx(a, hzn) / (1 + lambda(a, oz)) / (4 * oz);
        worst_f = std::max(worst_f, std::fabs(f.y - expect_f) / std::max(expect_f, 1e-3));
        worst_pdf = std::max(worst_pdf, std::fabs(pdf - expect_pdf) / std::max(expect_pdf, 1e-3));
      }
    }
  EXPECT_LT(worst_f, 2e-4);
  EXPECT_LT(worst_pdf, 2e-4);
}

TEST(FastMath, Atan2AndAcosMatchDoublePrecision) {
  double worst_atan = 0, worst_acos = 0;
  std::mt19937 rng(3);
  std::uniform_real_distribution<float> d(-1.0f, 1.0f);
  for (int i = 0; i < 200000; ++i) {
    const float y = d(rng), x = d(rng);
    worst_atan =
        std::max(worst_atan, std::fabs(atan2_fast(y, x) - std::atan2(double(y), double(x))));
    worst_acos = std::max(worst_acos, std::fabs(acos_fast(y) - std::acos(double(y))));
  }
  for (int i = 0; i <= 4096; ++i) {  // the axes, the diagonals and both ends of acos
    const float t = float(i) / 4096.0f;
    for (auto [y, x] : {std::pair{t, 1.0f}, {1.0f, t}, {-t, -1.0f}, {t, -1.0f}, {-1.0f, t}})
      worst_atan =
          std::max(worst_atan, std::fabs(atan2_fast(y, x) - std::atan2(double(y), double(x))));
    for (float x : {t, -t})
      worst_acos = std::max(worst_acos, std::fabs(acos_fast(x) - std::acos(double(x))));
  }
  EXPECT_LT(worst_atan, 4e-7);  // 1.2e-7 of the fit, and float rounding near pi (ulp 2.4e-7)
  EXPECT_LT(worst_acos, 5e-7);
  EXPECT_EQ(atan2_fast(0.0f, 0.0f), 0.0f);
  EXPECT_EQ(acos_fast(1.0f), 0.0f);
}

}  // namespace
}  // namespace kestrel::render
