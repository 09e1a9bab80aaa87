// The convolution kernels every network runs, against a double-precision oracle: each ISA's
// f32 kernel sums the products it is given; the bf16 kernel sums the products of the inputs
// and weights rounded to bf16 (to nearest, ties to even), and nothing else.
#include "nn/conv.h"

#include <gtest/gtest.h>

#include <bit>
#include <cmath>
#include <cstdint>
#include <random>
#include <vector>

#include "kestrel/isa.h"

namespace kestrel::nn {
namespace {

float round_bf16(float f) {  // finite, normal values
  uint32_t u = std::bit_cast<uint32_t>(f);
  u += 0x7FFFu + ((u >> 16) & 1u);
  return std::bit_cast<float>(u & 0xFFFF0000u);
}

struct Shape {
  int cin, cout, ksize, w, h;
};

struct Case {
  ConvLayer layer;
  std::vector<float> in;
};

Case make_case(const Shape& s, uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u(-1.0f, 1.0f);
  Case c;
  c.layer.cin = s.cin, c.layer.cout = s.cout, c.layer.ksize = s.ksize, c.layer.outputs = s.cout;
  c.layer.weights.resize(size_t(s.ksize * s.ksize) * size_t(s.cin) * size_t(s.cout));
  for (float& v : c.layer.weights) v = u(rng) * 0.5f;
  c.layer.bias.resize(size_t(s.cout));
  for (float& v : c.layer.bias) v = u(rng) * 0.1f;
  c.in.resize(size_t(s.w) * size_t(s.h) * size_t(s.cin));
  for (float& v : c.in) v = u(rng) < -0.6f ? 0.0f : u(rng) * 3.0f;  // some zeros, both signs
  return c;
}

// Output (x, y, co) in double from (optionally bf16-rounded) inputs and weights, zero padded;
// `magnitude` gets the sum of the terms' absolute values (the rounding error's scale).
double oracle(const Case& c, const Shape& s, bool bf16, int x, int y, int co, double& magnitude) {
  auto r = [&](float v) { return double(bf16 ? round_bf16(v) : v); };
  const int k = s.ksize, rad = k / 2;
  double sum = c.layer.bias[size_t(co)];
  magnitude = std::abs(sum);
  for (int ky = 0; ky < k; ++ky)
    for (int kx = 0; kx < k; ++kx) {
      const int sx = x + kx - rad, sy = y + ky - rad;
      if (sx < 0 || sy < 0 || sx >= s.w || sy >= s.h) continue;
      for (int ci = 0; ci < s.cin; ++ci) {
        const double t =
            r(c.in[(size_t(sy) * size_t(s.w) + size_t(sx)) * size_t(s.cin) + size_t(ci)]) *
            r(c.layer.weights[(size_t(ky * k + kx) * size_t(s.cin) + size_t(ci)) * size_t(s.cout) +
                              size_t(co)]);
        sum += t;
        magnitude += std::abs(t);
      }
    }
  return sum;
}

// Odd and even input channels (an odd count leaves half a bf16 pair), widths around the
// kernels' pixel blocks (8 and 16), 3x3 and 1x1, one and two 16-channel output blocks.
const Shape kShapes[] = {{11, 16, 3, 37, 9}, {16, 16, 3, 33, 5}, {18, 16, 3, 20, 7},
                         {48, 16, 3, 17, 6}, {16, 32, 1, 19, 4}, {3, 16, 3, 5, 3},
                         {33, 32, 3, 16, 2}};

// Runs `kernels` on every shape and checks every output against the oracle (rounded to bf16 or
// not) within the f32 summation's error; returns how many outputs sit further than that from
// the other oracle (to show the two are told apart).
int check(const ConvKernels& kernels, bool bf16) {
  int off_the_other = 0;
  uint32_t seed = 1;
  for (const Shape& s : kShapes) {
    SCOPED_TRACE(testing::Message() << "cin " << s.cin << " cout " << s.cout << " k " << s.ksize
                                    << " " << s.w << "x" << s.h);
    const Case c = make_case(s, seed++);
    for (bool relu : {false, true}) {
      // Scratch reused from a larger layer holds anything: NaN here, which every padding slot
      // and the half pair after an odd channel count must overwrite (0 x NaN is NaN).
      std::vector<float> out, scratch(size_t(1) << 16, std::nanf(""));
      kernels.conv(c.layer, c.in, s.w, s.h, out, relu, scratch);
      EXPECT_EQ(out.size(), size_t(s.w) * size_t(s.h) * size_t(s.cout));
      if (out.size() != size_t(s.w) * size_t(s.h) * size_t(s.cout)) return off_the_other;
      const double terms = double(s.ksize * s.ksize * s.cin + 1);
      for (int y = 0; y < s.h; ++y)
        for (int x = 0; x < s.w; ++x)
          for (int co = 0; co < s.cout; ++co) {
            double mag = 0, other_mag = 0;
            double want = oracle(c, s, bf16, x, y, co, mag);
            double other = oracle(c, s, !bf16, x, y, co, other_mag);
            if (relu) want = std::max(want, 0.0), other = std::max(other, 0.0);
            const double tol = terms * std::ldexp(mag, -23) + 1e-30;
            const float got =
                out[(size_t(y) * size_t(s.w) + size_t(x)) * size_t(s.cout) + size_t(co)];
            if (!(std::abs(got - want) <= tol)) {
              ADD_FAILURE() << "pixel " << x << "," << y << " output " << co << ": " << got
                            << " against " << want << " (tolerance " << tol << ")";
              return off_the_other;
            }
            off_the_other += std::abs(got - other) > tol;
          }
    }
  }
  return off_the_other;
}

TEST(ConvKernels, F32KernelsSumTheExactProducts) {
  for (Isa isa : {Isa::sse2, Isa::avx2, Isa::avx512}) {
    if (!isa_supported(isa)) continue;
    SCOPED_TRACE(isa_name(isa));
    EXPECT_GT(check(conv_kernels(isa), false), 0);  // rounding to bf16 would be noticed
  }
}

TEST(ConvKernels, Bf16KernelSumsTheRoundedProducts) {
  if (!conv_bf16_supported()) GTEST_SKIP() << "this CPU has no AVX-512 BF16";
  const ConvKernels& k = conv_kernels(Isa::avx512, true);
  EXPECT_STREQ(k.isa, "avx512-bf16");
  EXPECT_GT(check(k, true), 0);  // an f32 sum would be noticed
}

TEST(ConvKernels, Bf16IsAskedForOnlyWhereTheCpuHasIt) {
  // Other ISAs, and AVX-512 without BF16, keep their f32 kernel when bf16 is asked for.
  for (Isa isa : {Isa::sse2, Isa::avx2, Isa::avx512}) {
    if (!isa_supported(isa)) continue;
    const bool bf16 = isa == Isa::avx512 && conv_bf16_supported();
    EXPECT_EQ(&conv_kernels(isa, true), bf16 ? &conv_kernels_avx512_bf16() : &conv_kernels(isa))
        << isa_name(isa);
  }
}

}  // namespace
}  // namespace kestrel::nn
