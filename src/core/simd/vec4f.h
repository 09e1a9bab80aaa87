// 4-wide float vector over SSE2 (part of the x86-64 baseline, so no dispatch is needed).
// Used for box arithmetic in builders: a PrimRef or node half loads as one Vec4f.
#pragma once
#include <immintrin.h>

namespace kestrel::simd {

struct Vec4f {
  __m128 v;
  Vec4f() = default;
  explicit Vec4f(__m128 x) : v(x) {}
  explicit Vec4f(float s) : v(_mm_set1_ps(s)) {}
  static Vec4f load(const void* p) { return Vec4f(_mm_load_ps(static_cast<const float*>(p))); }
  static Vec4f loadu(const void* p) { return Vec4f(_mm_loadu_ps(static_cast<const float*>(p))); }
  void store(void* p) const { _mm_store_ps(static_cast<float*>(p), v); }
  void storeu(void* p) const { _mm_storeu_ps(static_cast<float*>(p), v); }
  float operator[](int i) const {
    alignas(16) float f[4];
    _mm_store_ps(f, v);
    return f[i];
  }
};
inline Vec4f operator+(Vec4f a, Vec4f b) {
  return Vec4f(_mm_add_ps(a.v, b.v));
}
inline Vec4f operator-(Vec4f a, Vec4f b) {
  return Vec4f(_mm_sub_ps(a.v, b.v));
}
inline Vec4f operator*(Vec4f a, Vec4f b) {
  return Vec4f(_mm_mul_ps(a.v, b.v));
}
inline Vec4f min(Vec4f a, Vec4f b) {
  return Vec4f(_mm_min_ps(a.v, b.v));
}
inline Vec4f max(Vec4f a, Vec4f b) {
  return Vec4f(_mm_max_ps(a.v, b.v));
}
/// Truncating float -> int32 per lane, stored to out[4].
inline void to_int(Vec4f a, int* out) {
  _mm_storeu_si128(reinterpret_cast<__m128i*>(out), _mm_cvttps_epi32(a.v));
}
/// a with lane 3 zero. Builders keep a prim id in lane 3 of a box corner (PrimRef::lo), whose
/// bits read as a denormal float, and x86 arithmetic on denormals takes a microcode assist
/// (binned SAH binning ran at half speed): lane 3 is cleared before any arithmetic.
inline Vec4f clear_w(Vec4f a) {
  return Vec4f(_mm_and_ps(a.v, _mm_castsi128_ps(_mm_setr_epi32(-1, -1, -1, 0))));
}
/// Half surface area of the box [lo, hi] (lanes 0..2), 0 if empty on any axis.
/// d.x*d.y + d.y*d.z + d.z*d.x as d * d.yzx, summed over lanes 0..2, all in registers.
/// Lane 3 is cleared first (see clear_w).
inline float half_area(Vec4f lo, Vec4f hi) {
  const __m128 d = _mm_max_ps(_mm_sub_ps(clear_w(hi).v, clear_w(lo).v), _mm_setzero_ps());
  const __m128 p = _mm_mul_ps(d, _mm_shuffle_ps(d, d, _MM_SHUFFLE(3, 0, 2, 1)));
  __m128 s = _mm_add_ss(p, _mm_shuffle_ps(p, p, _MM_SHUFFLE(1, 1, 1, 1)));
  s = _mm_add_ss(s, _mm_movehl_ps(p, p));
  return _mm_cvtss_f32(s);
}

}  // namespace kestrel::simd
