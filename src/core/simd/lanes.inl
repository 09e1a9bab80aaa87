// GCC vector-extension helpers for per-ISA kernels (the denoisers' kernels.inl and
// svgf_kernels.inl, the upsampler's reconstruct.inl), included inside each ISA's namespace
// after <immintrin.h>, <cmath> and <cstring>.
//
// A hot loop's body is written once as a template over T = float (borders, the tail of a
// row) and T = vfloat (the interior, kLanes pixels at a time), so it is vectorised on every
// ISA whatever the auto-vectoriser decides (it gave up on the neural filter's loop under
// AVX2 and SSE2: "control flow in loop", and ran it scalar). The vector forms of exp_neg and
// log1p_pos do the scalar forms' operations lane by lane.

// exp(x) for x <= 0 (0 below -80): 2^(x log2 e) = 2^n * 2^f, 2^f by its degree-6 Taylor
// polynomial on [-0.5, 0.5] (relative error < 2e-7). Integer tricks only, so it vectorises.
static inline float exp_neg(float x) {
  const bool tiny = x < -80.0f;  // below e^-80 the result is 0: no denormals downstream
  x = tiny ? -80.0f : x;
  const float t = x * 1.44269504f;
  // t + 1.5 * 2^23 rounds t to the nearest integer n, held in the low mantissa bits.
  const float shifted = t + 12582912.0f;
  const float f = t - (shifted - 12582912.0f);
  float p = 1.5403530e-4f;
  p = p * f + 1.3333558e-3f;
  p = p * f + 9.6181291e-3f;
  p = p * f + 5.5504109e-2f;
  p = p * f + 2.4022651e-1f;
  p = p * f + 6.9314718e-1f;
  p = p * f + 1.0f;
  const int n = __builtin_bit_cast(int, shifted) - 0x4B400000;
  return tiny ? 0.0f : p * __builtin_bit_cast(float, (n + 127) << 23);
}

// log(1 + v) for v >= 0: u = 1 + v = m 2^e, m in [sqrt(1/2), sqrt(2)), log m by the atanh
// series (s = (m-1)/(m+1), |s| < 0.172, 5 terms): absolute error < 1e-7.
static inline float log1p_pos(float v) {
  const float u = 1.0f + v;
  const int bits = __builtin_bit_cast(int, u);
  int e = ((bits >> 23) & 255) - 127;
  float m = __builtin_bit_cast(float, (bits & 0x7FFFFF) | 0x3F800000);
  const bool big = m > 1.41421356f;
  m = big ? m * 0.5f : m;
  e = big ? e + 1 : e;
  const float s = (m - 1.0f) / (m + 1.0f), s2 = s * s;
  const float series =
      s * (2.0f + s2 * (0.6666667f + s2 * (0.4f + s2 * (0.2857143f + s2 * 0.2222222f))));
  return float(e) * 0.69314718f + series;
}

#if defined(__AVX512F__)
static constexpr int kLanes = 16;
#elif defined(__AVX2__)
static constexpr int kLanes = 8;
#else
static constexpr int kLanes = 4;
#endif
static constexpr float kLog2e = 1.44269504f;
typedef float vfloat __attribute__((vector_size(4 * kLanes)));
typedef int vint __attribute__((vector_size(4 * kLanes)));

template <class T>
static inline T ld(const float* p) {
  T v;
  std::memcpy(&v, p, sizeof v);
  return v;
}
template <class T>
static inline void st(float* p, T v) {
  std::memcpy(p, &v, sizeof v);
}
static inline float vabs(float x) {
  return std::fabs(x);
}
static inline vfloat vabs(vfloat x) {
  return (vfloat)((vint)x & 0x7FFFFFFF);
}
static inline float vmax(float a, float b) {
  return a < b ? b : a;
}
static inline vfloat vmax(vfloat a, vfloat b) {
  return a < b ? b : a;
}
static inline float vsqrt(float x) {
  return std::sqrt(x);
}
static inline vfloat vsqrt(vfloat x) {
#if defined(__AVX512F__)
  return (vfloat)_mm512_mask_sqrt_ps((__m512)x, 0xFFFF, (__m512)x);  // no undefined source
#elif defined(__AVX2__)
  return (vfloat)_mm256_sqrt_ps((__m256)x);
#else
  return (vfloat)_mm_sqrt_ps((__m128)x);
#endif
}
// Lane l of the result: base[idx[l]].
static inline vfloat vgather(const float* base, vint idx) {
#if defined(__AVX512F__)
  return (vfloat)_mm512_mask_i32gather_ps(_mm512_setzero_ps(), 0xFFFF, (__m512i)idx, base, 4);
#elif defined(__AVX2__)
  return (vfloat)_mm256_i32gather_ps(base, (__m256i)idx, 4);
#else
  vfloat v;
  for (int l = 0; l < kLanes; ++l) v[l] = base[idx[l]];
  return v;
#endif
}
// Float <-> int lane by lane (truncation), int stores, and the lanes' column indices.
static inline int vtrunc(float x) {
  return int(x);
}
static inline vint vtrunc(vfloat x) {
  return __builtin_convertvector(x, vint);
}
static inline float vfloat_of(int x) {
  return float(x);
}
static inline vfloat vfloat_of(vint x) {
  return __builtin_convertvector(x, vfloat);
}
static inline void sti(int* p, int v) {
  *p = v;
}
static inline void sti(int* p, vint v) {
  std::memcpy(p, &v, sizeof v);
}
static inline float vindex(float, int i) {
  return float(i);
}
static inline vfloat vindex(vfloat, int i) {
  vfloat v;
  for (int l = 0; l < kLanes; ++l) v[l] = float(i + l);
  return v;
}
static inline float vexp_neg(float x) {
  return exp_neg(x);
}
// exp_neg lane by lane: the same operations, so the same bits.
static inline vfloat vexp_neg(vfloat x) {
  const vint tiny = x < -80.0f;
  x = tiny ? vfloat{} - 80.0f : x;
  const vfloat t = x * 1.44269504f;
  const vfloat shifted = t + 12582912.0f;
  const vfloat f = t - (shifted - 12582912.0f);
  vfloat p = vfloat{} + 1.5403530e-4f;
  p = p * f + 1.3333558e-3f;
  p = p * f + 9.6181291e-3f;
  p = p * f + 5.5504109e-2f;
  p = p * f + 2.4022651e-1f;
  p = p * f + 6.9314718e-1f;
  p = p * f + 1.0f;
  const vint n = (vint)shifted - 0x4B400000;
  return tiny ? vfloat{} : p * (vfloat)((n + 127) << 23);
}
// 2^y (0 below 2^-115 ~ e^-80, and for y = -inf or NaN): 2^n 2^f with 2^f by a degree-5
// minimax polynomial on [-0.5, 0.5] (relative error 8e-8). The filters' weights: log2 e folds
// into their edge stops' scales and a tap's spline weight into the exponent (log2 h; -inf
// for a tap outside the image), saving the exp's scaling, a multiply and a polynomial term.
static inline float vexp2(float y) {
  const bool tiny = !(y >= -115.0f);
  y = tiny ? -115.0f : y;
  const float shifted = y + 12582912.0f, f = y - (shifted - 12582912.0f);
  const float p =
      1.0000001f +
      f * (0.69314694f +
           f * (0.2402212f + f * (0.05550715f + f * (0.009675536f + f * 0.0013275768f))));
  const int n = __builtin_bit_cast(int, shifted) - 0x4B400000;
  return tiny ? 0.0f : p * __builtin_bit_cast(float, (n + 127) << 23);
}
static inline vfloat vexp2(vfloat y) {
#if defined(__AVX512F__)
  // The same n, f and polynomial, so the same bits: 2^n applied by vscalefps (exact), the lanes
  // below -115 (and NaN) zeroed by its mask: 9 instructions instead of 15.
  const __mmask16 ok = _mm512_cmp_ps_mask((__m512)y, _mm512_set1_ps(-115.0f), _CMP_GE_OQ);
  const vfloat n = (vfloat)_mm512_mask_roundscale_ps(  // no undefined source (as vsqrt)
      (__m512)y, 0xFFFF, (__m512)y, _MM_FROUND_TO_NEAREST_INT | _MM_FROUND_NO_EXC);
  const vfloat f = y - n;
  const vfloat p =
      1.0000001f +
      f * (0.69314694f +
           f * (0.2402212f + f * (0.05550715f + f * (0.009675536f + f * 0.0013275768f))));
  return (vfloat)_mm512_maskz_scalef_ps(ok, (__m512)p, (__m512)n);
#else
  const vint tiny = !(y >= -115.0f);
  y = tiny ? vfloat{} - 115.0f : y;
  const vfloat shifted = y + 12582912.0f, f = y - (shifted - 12582912.0f);
  const vfloat p =
      1.0000001f +
      f * (0.69314694f +
           f * (0.2402212f + f * (0.05550715f + f * (0.009675536f + f * 0.0013275768f))));
  const vint n = (vint)shifted - 0x4B400000;
  return tiny ? vfloat{} : p * (vfloat)((n + 127) << 23);
#endif
}
static inline float vlog1p_pos(float v) {
  return log1p_pos(v);
}
// log1p_pos lane by lane.
static inline vfloat vlog1p_pos(vfloat v) {
  const vfloat u = 1.0f + v;
  const vint bits = (vint)u;
  vint e = ((bits >> 23) & 255) - 127;
  vfloat m = (vfloat)((bits & 0x7FFFFF) | 0x3F800000);
  const vint big = m > 1.41421356f;
  m = big ? m * 0.5f : m;
  e = big ? e + 1 : e;
  const vfloat s = (m - 1.0f) / (m + 1.0f), s2 = s * s;
  const vfloat series =
      s * (2.0f + s2 * (0.6666667f + s2 * (0.4f + s2 * (0.2857143f + s2 * 0.2222222f))));
  return __builtin_convertvector(e, vfloat) * 0.69314718f + series;
}

// Calls f(T{}, i) for i in [lo, hi): T = vfloat for the pixels i .. i + kLanes - 1 while
// they fit, then T = float one by one. f loads and stores with ld<T> / st.
template <class F>
static inline void for_lanes_in(int lo, int hi, F&& f) {
  int i = lo;
  for (; i + kLanes <= hi; i += kLanes) f(vfloat{}, i);
  for (; i < hi; ++i) f(0.0f, i);
}
template <class F>
static inline void for_lanes(int n, F&& f) {
  for_lanes_in(0, n, f);
}

// ---- Integer lanes, lookups and lane tests (the upsampler's reconstruction). ----

// The lane count of T (1 for the scalar form) and T's integer lanes.
template <class T>
static constexpr int lanes_of = sizeof(T) / sizeof(float);
template <class T>
using lanes_int = decltype(vtrunc(T{}));

static inline float vmin(float a, float b) {
  return b < a ? b : a;
}
static inline vfloat vmin(vfloat a, vfloat b) {
  return b < a ? b : a;
}
static inline int vmaxi(int a, int b) {
  return a < b ? b : a;
}
static inline vint vmaxi(vint a, vint b) {
  return a < b ? b : a;
}
static inline int vmini(int a, int b) {
  return b < a ? b : a;
}
static inline vint vmini(vint a, vint b) {
  return b < a ? b : a;
}
template <class I>
static inline I ldi(const int* p) {
  I v;
  std::memcpy(&v, p, sizeof v);
  return v;
}
// floor as an int (|x| < 2^31).
static inline int vfloor(float x) {
  const int i = int(x);
  return i - (float(i) > x);
}
static inline vint vfloor(vfloat x) {
  const vint i = __builtin_convertvector(x, vint);
  return i + (vint)(__builtin_convertvector(i, vfloat) > x);  // true is -1
}
static inline float vgather(const float* base, int idx) {
  return base[idx];
}
// Not, lane by lane, for a comparison's result (bool, or a vector's -1 / 0 lanes).
static inline bool vnot(bool m) {
  return !m;
}
static inline vint vnot(vint m) {
  return ~m;
}
// True when every lane's mask is set.
static inline bool all_of(bool m) {
  return m;
}
static inline bool all_of(vint m) {
#if defined(__AVX512F__)
  return _mm512_cmpneq_epi32_mask((__m512i)m, _mm512_setzero_si512()) == 0xFFFF;
#elif defined(__AVX2__)
  return _mm256_movemask_ps((__m256)m) == 0xFF;
#else
  return _mm_movemask_ps((__m128)m) == 0xF;
#endif
}
// True when some lane's mask is set.
static inline bool any_of(bool m) {
  return m;
}
static inline bool any_of(vint m) {
  return !all_of(~m);
}
// base[idx[l]] for indices known to lie in [lo, hi], with base[lo .. lo + kLanes) readable:
// one load and a permute where they span fewer than kLanes entries, a gather otherwise.
static inline float lookup(const float* base, int idx, int, int) {
  return base[idx];
}
static inline vfloat lookup(const float* base, vint idx, int lo, int hi) {
#if defined(__AVX512F__)
  if (hi - lo < kLanes)
    return (vfloat)_mm512_maskz_permutexvar_ps(0xFFFF, (__m512i)(idx - lo),  // no undefined
                                               _mm512_loadu_ps(base + lo));  // source
#elif defined(__AVX2__)
  if (hi - lo < kLanes)
    return (vfloat)_mm256_permutevar8x32_ps(_mm256_loadu_ps(base + lo), (__m256i)(idx - lo));
#endif
  return vgather(base, idx);
}
// 0, 1, 2, ... (the scalar form: 0).
static inline int lane_iota(int) {
  return 0;
}
static inline vint lane_iota(vint) {
  vint v;
  for (int l = 0; l < kLanes; ++l) v[l] = l;
  return v;
}
// Lane l: row[clamp(col + l, 0, w - 1)] (an image row's pixels, its edge pixels repeated
// beyond it; w >= 1). Masked loads read only the lanes inside the row (no gather).
static inline float ld_clamped(const float* row, int col, int w) {
  return row[col < 0 ? 0 : (col >= w ? w - 1 : col)];
}
static inline vfloat ld_clamped(vfloat, const float* row, int col, int w) {
  if (col >= 0 && col + kLanes <= w) return ld<vfloat>(row + col);
  const vint c = lane_iota(vint{}) + col;
  const vint in = (c >= 0) & (c < w);
  const vfloat edge = c < 0 ? vfloat{} + row[0] : vfloat{} + row[w - 1];
#if defined(__AVX512F__)
  const __mmask16 m = _mm512_cmpneq_epi32_mask((__m512i)in, _mm512_setzero_si512());
  return (vfloat)_mm512_mask_loadu_ps((__m512)edge, m, row + col);
#elif defined(__AVX2__)
  return in ? (vfloat)_mm256_maskload_ps(row + col, (__m256i)in) : edge;
#else
  vfloat v;
  for (int l = 0; l < kLanes; ++l) v[l] = in[l] ? row[col + l] : edge[l];
  return v;
#endif
}
// Channels-last RGB from three planes' lanes: dst[3 l + c] = lane l of channel c.
static inline void st_rgb(float* dst, float r, float g, float b) {
  dst[0] = r, dst[1] = g, dst[2] = b;
}
// Four pixels' channels as (r, g, b, 0) rows, from four lanes of each channel.
static inline void rgb_rows(__m128 r, __m128 g, __m128 b, __m128 p[4]) {
  const __m128 z = _mm_setzero_ps();
  const __m128 rg0 = _mm_unpacklo_ps(r, g), rg1 = _mm_unpackhi_ps(r, g);
  const __m128 b0 = _mm_unpacklo_ps(b, z), b1 = _mm_unpackhi_ps(b, z);
  p[0] = _mm_movelh_ps(rg0, b0), p[1] = _mm_movehl_ps(b0, rg0);
  p[2] = _mm_movelh_ps(rg1, b1), p[3] = _mm_movehl_ps(b1, rg1);
}
// Four pixels from their rows: overlapping 4-float stores, the last one 3 floats (nothing
// past dst[11] is written).
static inline void st_rgb_rows(float* dst, const __m128 p[4]) {
  _mm_storeu_ps(dst, p[0]);
  _mm_storeu_ps(dst + 3, p[1]);
  _mm_storeu_ps(dst + 6, p[2]);
  _mm_storel_pi((__m64*)(dst + 9), p[3]);
  _mm_store_ss(dst + 11, _mm_movehl_ps(p[3], p[3]));
}
static inline void st_rgb(float* dst, vfloat r, vfloat g, vfloat b) {
#if defined(__AVX512F__)
  for (int l = 0; l < kLanes; ++l) dst[3 * l] = r[l], dst[3 * l + 1] = g[l], dst[3 * l + 2] = b[l];
#elif defined(__AVX2__)
  __m128 p[4];
  rgb_rows(_mm256_castps256_ps128((__m256)r), _mm256_castps256_ps128((__m256)g),
           _mm256_castps256_ps128((__m256)b), p);
  st_rgb_rows(dst, p);
  rgb_rows(_mm256_extractf128_ps((__m256)r, 1), _mm256_extractf128_ps((__m256)g, 1),
           _mm256_extractf128_ps((__m256)b, 1), p);
  st_rgb_rows(dst + 12, p);
#else
  __m128 p[4];
  rgb_rows((__m128)r, (__m128)g, (__m128)b, p);
  st_rgb_rows(dst, p);
#endif
}
// Lane l of the result: entry idx[l] of the 2 kLanes entries lo, hi (idx in [0, 2 kLanes)).
static inline vfloat perm2(vfloat lo, vfloat hi, vint idx) {
#if defined(__AVX512F__)
  return (vfloat)_mm512_permutex2var_ps((__m512)lo, (__m512i)idx, (__m512)hi);
#elif defined(__AVX2__)
  const __m256 a = _mm256_permutevar8x32_ps((__m256)lo, (__m256i)idx);
  const __m256 b = _mm256_permutevar8x32_ps((__m256)hi, (__m256i)idx);
  return (vfloat)_mm256_blendv_ps(a, b, _mm256_castsi256_ps(_mm256_slli_epi32((__m256i)idx, 28)));
#else
  vfloat v;
  for (int l = 0; l < kLanes; ++l) v[l] = idx[l] < kLanes ? lo[idx[l]] : hi[idx[l] - kLanes];
  return v;
#endif
}
// The smallest and largest lane.
static inline int lane_min(int v) {
  return v;
}
static inline int lane_max(int v) {
  return v;
}
#if defined(__AVX2__)
// min or max of the 8 lanes of m (AVX2).
template <bool kMax>
static inline int lane_reduce8(__m256i m) {
  auto op = [](__m256i x, __m256i y) {
    return kMax ? _mm256_max_epi32(x, y) : _mm256_min_epi32(x, y);
  };
  m = op(m, _mm256_permute2x128_si256(m, m, 1));
  m = op(m, _mm256_shuffle_epi32(m, 0x4E));
  m = op(m, _mm256_shuffle_epi32(m, 0xB1));
  return _mm256_cvtsi256_si32(m);
}
#endif
template <bool kMax>
static inline int lane_reduce(vint v) {
#if defined(__AVX512F__)
  // The two halves first (as 8-lane vectors: GCC 12's _mm512_reduce_* and 512-to-256 casts
  // warn of an undefined register).
  typedef int v8i __attribute__((vector_size(32)));
  v8i lo, hi;
  std::memcpy(&lo, &v, sizeof lo);
  std::memcpy(&hi, reinterpret_cast<const char*>(&v) + sizeof lo, sizeof hi);
  return lane_reduce8<kMax>((__m256i)(kMax ? (lo > hi ? lo : hi) : (lo < hi ? lo : hi)));
#elif defined(__AVX2__)
  return lane_reduce8<kMax>((__m256i)v);
#else
  int m = v[0];
  for (int l = 1; l < kLanes; ++l) m = kMax ? (v[l] > m ? v[l] : m) : (v[l] < m ? v[l] : m);
  return m;
#endif
}
static inline int lane_min(vint v) {
  return lane_reduce<false>(v);
}
static inline int lane_max(vint v) {
  return lane_reduce<true>(v);
}
