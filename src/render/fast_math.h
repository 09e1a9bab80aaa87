// Trigonometry for the shading loop at float accuracy without libm calls: the angles it takes
// are 2 pi u for a uniform u (disk, cosine, sun-cone and visible-normal samples) and the
// latitude-longitude of a direction (the sky's texel). libm's sincosf, atan2f and acosf were
// ~2.5 % of a real-time frame inside Sponza (perf, 2026-12-05); these are a few multiply-adds
// each, with errors below 4e-7 (tests/render/bsdf_test.cpp checks them against double
// precision).
#pragma once
#include <bit>
#include <cmath>
#include <cstdint>

namespace kestrel::render {

/// c[0] + c[1] x + ... + c[N-1] x^(N-1), by Horner's rule.
template <int N>
inline float polynomial(float x, const float (&c)[N]) {
  float p = c[N - 1];
  for (int k = N - 2; k >= 0; --k) p = p * x + c[k];
  return p;
}

/// std::nearbyint in the default rounding mode (to nearest, ties to even) without a libm call
/// (baseline x86-64 has no rounding instruction): |x| + 2^23 is rounded to an integer by the
/// addition itself and the subtraction is exact; floats of at least 2^23 are integers.
inline float round_even(float x) {
  const float a = std::fabs(x);
  if (!(a < 0x1p23f)) return x;  // also NaN and the infinities
  return std::copysign((a + 0x1p23f) - 0x1p23f, x);
}

/// std::floor without a libm call (baseline x86-64 has no rounding instruction), the same
/// value for every float: the truncation, one lower where it rounded up (negative
/// non-integers); floats of at least 2^23 are integers; -0 stays -0.
inline float floor_exact(float x) {
  if (!(std::fabs(x) < 0x1p23f)) return x;  // also NaN and the infinities
  float t = float(int(x));
  if (t > x) t -= 1.0f;
  return std::copysign(t, x);
}

/// sin and cos of t in [-pi/4, pi/4] by the Taylor series to the 9th (sin) and 10th (cos)
/// power, whose remainder is below 2e-9 there: sincos_2pi's core, of a float or of a vector of
/// them (the SIMD lanes of render/surface_rows.inl do the same operations).
template <class T>
inline void sincos_taylor(T t, T& sn, T& cs) {
  const T t2 = t * t;
  sn = t *
       (1.0f + t2 * (-1.0f / 6 + t2 * (1.0f / 120 + t2 * (-1.0f / 5040 + t2 * (1.0f / 362880)))));
  cs = 1.0f + t2 * (-0.5f + t2 * (1.0f / 24 + t2 * (-1.0f / 720 +
                                                    t2 * (1.0f / 40320 + t2 * (-1.0f / 3628800)))));
}

/// sin and cos of k quarter turns plus t from those of t (sn, cs): the quadrant's swap and
/// signs as bit operations on B (uint32_t, or a vector of 32-bit integers for a vector T: the
/// SIMD lanes of render/surface_rows.inl), since k is as random as the angle and branches on
/// it would mispredict half the time. k: 0, 1, 2, 3 (= -1).
template <class T, class B>
inline void sincos_quadrant(B k, T sn, T cs, T& s, T& c) {
  const B swap = 0 - (k & 1), bs = __builtin_bit_cast(B, sn), bc = __builtin_bit_cast(B, cs);
  const B a = (bs & ~swap) | (bc & swap), b = (bc & ~swap) | (bs & swap);
  s = __builtin_bit_cast(T, B(a ^ ((k >> 1) << 31)));              // negated for k = 2, 3
  c = __builtin_bit_cast(T, B(b ^ ((((k + 1) >> 1) & 1) << 31)));  // negated for k = 1, 2
}

/// sin and cos of 2 pi u, for any finite u: reduced to a quarter turn around 0 and evaluated
/// by sincos_taylor; the quadrant's swap and signs are then exact (sincos_quadrant).
inline void sincos_2pi(float u, float& s, float& c) {
  const float r = u - round_even(u);              // [-1/2, 1/2] turns
  const float q = round_even(4.0f * r);           // quadrant -2 .. 2
  const float t = (r - 0.25f * q) * 6.28318531f;  // [-pi/4, pi/4]
  float sn, cs;
  sincos_taylor(t, sn, cs);
  sincos_quadrant(uint32_t(int(q)) & 3u, sn, cs, s, c);
}

/// atan2(y, x) in [-pi, pi]: an odd polynomial in min / max of |x| and |y| (degree 15, fitted
/// to arctan on [0, 1]; error 1.2e-7), then the octant's reflections. (0, 0) gives 0.
inline float atan2_fast(float y, float x) {
  const float ax = std::fabs(x), ay = std::fabs(y);
  const float hi = ax > ay ? ax : ay, lo = ax > ay ? ay : ax;
  const float z = hi > 0 ? lo / hi : 0.0f, z2 = z * z;
  constexpr float c[] = {0.9999993443489075f,   -0.33329862356185913f, 0.19946567714214325f,
                         -0.13908633589744568f, 0.09642203897237778f,  -0.055912356823682785f,
                         0.021862952038645744f, -0.004054560326039791f};
  const float p = polynomial(z2, c);
  float a = p * z;
  if (ay > ax) a = 1.57079633f - a;
  if (x < 0) a = 3.14159265f - a;
  return std::signbit(y) ? -a : a;
}

/// acos(x) for x in [-1, 1]: sqrt(1 - |x|) times a degree-7 polynomial (fitted; the form of
/// Abramowitz & Stegun 4.4.45), error 2.4e-7; pi - acos(-x) below 0.
inline float acos_fast(float x) {
  const float ax = std::fabs(x);
  constexpr float c[] = {1.5707963705062866f,    -0.21459989249706268f,  0.08899930864572525f,
                         -0.050313130021095276f, 0.03133669123053551f,   -0.01781114749610424f,
                         0.007247313391417265f,  -0.0014421025989577174f};
  const float p = polynomial(ax, c);
  const float a = std::sqrt(1.0f - ax) * p;
  return x < 0 ? 3.14159265f - a : a;
}

}  // namespace kestrel::render
