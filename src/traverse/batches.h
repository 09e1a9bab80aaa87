// Splitting a batch of rays into the runs the kernels may see. Not included by the per-ISA
// kernel files (its inline functions must be compiled for the baseline ISA only).
#pragma once
#include <emmintrin.h>

#include <cstddef>
#include <span>

#include "geometry/triangle_intersect.h"

namespace kestrel::kernels {

/// is_traceable(r) in a few SSE compares and one test instead of a chain of branches: the
/// scan below runs on every ray of every batch (6-9 % of a packet trace of Sponza's camera
/// rays either way, being their first read from memory; the chain's branches were the rest).
/// The ray's floats are read as [org.x org.y org.z dir.x] and [dir.y dir.z tmin tmax].
inline bool is_traceable_fast(const Ray& r) {
  static_assert(sizeof(Ray) == 8 * sizeof(float), "Ray: org, dir, tmin, tmax");
  const float* f = &r.org.x;
  const __m128 a = _mm_loadu_ps(f), b = _mm_loadu_ps(f + 4);
  const __m128 magnitude = _mm_castsi128_ps(_mm_set1_epi32(0x7FFFFFFF));
  const __m128 inf = _mm_set1_ps(__builtin_inff()), zero = _mm_setzero_ps();
  // a: every lane finite. b: dir.y, dir.z finite; tmin <= tmax (false with a NaN); tmax
  // ordered. The direction: some component non-zero.
  const int finite_a = _mm_movemask_ps(_mm_cmplt_ps(_mm_and_ps(a, magnitude), inf));
  const int finite_b = _mm_movemask_ps(_mm_cmplt_ps(_mm_and_ps(b, magnitude), inf));
  const int ordered_b =
      _mm_movemask_ps(_mm_cmple_ps(b, _mm_shuffle_ps(b, b, _MM_SHUFFLE(3, 3, 1, 0))));
  const int nonzero =
      (_mm_movemask_ps(_mm_cmpneq_ps(a, zero)) & 8) | (_mm_movemask_ps(_mm_cmpneq_ps(b, zero)) & 3);
  const int all = finite_a << 4 | (finite_b & 3) | (ordered_b & 0xC) | (nonzero != 0) << 8;
  return all == 0x1FF;
}

/// Calls fn(rays, out, n) on each run of traceable rays (finite, non-zero direction,
/// tmin <= tmax) and writes a default Out (a miss) for every other ray: kernels only ever
/// see rays that can hit.
template <class Out, class Fn>
void for_each_traceable_run(std::span<const Ray> rays, Out* out, Fn&& fn) {
  size_t i = 0;
  const size_t n = rays.size();
  while (i < n) {
    size_t j = i;
    while (j < n && is_traceable_fast(rays[j])) ++j;
    if (j > i) fn(rays.data() + i, out + i, j - i);
    if (j < n) out[j] = Out{};
    i = j + 1;
  }
}

}  // namespace kestrel::kernels
