// The BSDF's sampling against its own pdf, for the BSDF and glass tests: a chi-square test of
// bsdf_sample's directions binned in (theta, phi) against bsdf_pdf integrated per bin (sub x
// sub points a bin), over the hemisphere above the surface or the whole sphere; samples that
// fail are a cell of their own (expected: what the pdf leaves of 1).
#pragma once
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>
#include <string>
#include <vector>

#include "render/bsdf.h"
#include "support/oracles.h"

namespace kestrel::render {

inline Vec3 dir(double theta, double phi) {
  return {float(std::sin(theta) * std::cos(phi)), float(std::sin(theta) * std::sin(phi)),
          float(std::cos(theta))};
}

struct SamplingCheck {
  double total = 0;  // the pdf's integral over the bins
  int below = 0;     // samples below the surface
};

// 10^6 samples; fails the test (naming `what`) where the histogram disagrees with the pdf.
inline SamplingCheck expect_sampling_matches_pdf(const BsdfParams& p, Vec3 wo, bool sphere, int sub,
                                                 unsigned seed, const std::string& what) {
  const int nt = sphere ? 48 : 24, np = 48, samples = 1'000'000;
  std::vector<double> expected(size_t(nt * np), 0.0), observed(size_t(nt * np + 1), 0.0);
  const double dt = (sphere ? pi : pi / 2) / nt, dp = 2 * pi / np;
  SamplingCheck r;
  for (int i = 0; i < nt; ++i)
    for (int j = 0; j < np; ++j) {
      double e = 0;
      for (int a = 0; a < sub; ++a)
        for (int b = 0; b < sub; ++b) {
          const double t = (i + (a + 0.5) / sub) * dt, ph = (j + (b + 0.5) / sub) * dp;
          e += bsdf_pdf(p, wo, dir(t, ph)) * std::sin(t) * (dt / sub) * (dp / sub);
        }
      expected[size_t(i * np + j)] = e * samples;
      r.total += e;
    }
  std::mt19937 gen(seed);
  std::uniform_real_distribution<float> u(0.0f, 0x1.fffffep-1f);
  for (int s = 0; s < samples; ++s) {
    BsdfSample bs;
    if (!bsdf_sample(p, wo, u(gen), u(gen), u(gen), bs)) {
      observed[size_t(nt * np)] += 1;
      continue;
    }
    r.below += bs.wi.z < 0;
    const double t = std::acos(std::clamp(double(bs.wi.z), -1.0, 1.0));
    double ph = std::atan2(double(bs.wi.y), double(bs.wi.x));
    if (ph < 0) ph += 2 * pi;
    const int i = std::min(nt - 1, int(t / dt)), j = std::min(np - 1, int(ph / dp));
    observed[size_t(i * np + j)] += 1;
  }
  expected.push_back(std::max(0.0, (1.0 - r.total) * samples));
  const test::ChiSquare c2 = test::chi_square(expected, observed);
  if (c2.pool_expected < 5)
    EXPECT_LT(c2.pool_observed, 30) << what << ": samples where the pdf is ~0";
  EXPECT_GT(c2.p, 1e-4) << what << ": chi2 " << c2.chi2 << " over " << c2.cells << " cells";
  return r;
}

}  // namespace kestrel::render
