// GCC vector-extension helpers for the denoisers' per-ISA kernels, included by kernels.inl
// (after the scalar exp_neg and log1p_pos) inside each kernels_<isa>.cpp's namespace.
//
// A hot loop's body is written once as a template over T = float (borders, the tail of a
// row) and T = vfloat (the interior, kLanes pixels at a time), so it is vectorised on every
// ISA whatever the auto-vectoriser decides (it gave up on the neural filter's loop under
// AVX2 and SSE2: "control flow in loop", and ran it scalar). The vector forms of exp_neg and
// log1p_pos do the scalar forms' operations lane by lane.

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
  const vint tiny = !(y >= -115.0f);
  y = tiny ? vfloat{} - 115.0f : y;
  const vfloat shifted = y + 12582912.0f, f = y - (shifted - 12582912.0f);
  const vfloat p =
      1.0000001f +
      f * (0.69314694f +
           f * (0.2402212f + f * (0.05550715f + f * (0.009675536f + f * 0.0013275768f))));
  const vint n = (vint)shifted - 0x4B400000;
  return tiny ? vfloat{} : p * (vfloat)((n + 127) << 23);
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
