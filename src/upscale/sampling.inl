// Per-pixel helpers of the upsampler, included into each instruction set's namespace (the
// reconstruction files) and into upscale.cpp's, so no inline function compiled with one
// ISA's flags is shared with code compiled for another.
static inline float luma(const float* c) {
  return kLuma[0] * c[0] + kLuma[1] * c[1] + kLuma[2] * c[2];
}
static inline float finite_or_zero(float v) {
  return std::isfinite(v) ? v : 0.0f;
}
static inline int clampi(int v, int lo, int hi) {
  return v < lo ? lo : (v > hi ? hi : v);
}
// floor as an int without libm (baseline x86-64 has no roundss); |x| < 2^31.
static inline int floor_int(float x) {
  const int i = int(x);
  return i - (float(i) > x);
}
static inline float sigmoid(float x) {
  return 1.0f / (1.0f + std::exp(-x));
}
static inline float softplus(float x) {
  return x > 20.0f ? x : std::log1p(std::exp(x));
}

// Catmull-Rom weights of the four taps around t in [0, 1).
static inline void catmull_rom(float t, float w[4]) {
  const float t2 = t * t, t3 = t2 * t;
  w[0] = -0.5f * t3 + t2 - 0.5f * t;
  w[1] = 1.5f * t3 - 2.5f * t2 + 1.0f;
  w[2] = -1.5f * t3 + 2.0f * t2 + 0.5f * t;
  w[3] = 0.5f * t3 - 0.5f * t2;
}

// Samples a channels-last image (c channels) at continuous coordinates, pixel centres at
// k + 0.5, edges clamped: bilinear or Catmull-Rom.
template <int C>
static inline void sample_bilinear(const float* img, int w, int h, float x, float y, float* out) {
  const float xf = x - 0.5f, yf = y - 0.5f;
  const int x0 = floor_int(xf), y0 = floor_int(yf);
  const float tx = xf - float(x0), ty = yf - float(y0);
  const int ix0 = clampi(x0, 0, w - 1), ix1 = clampi(x0 + 1, 0, w - 1);
  const int iy0 = clampi(y0, 0, h - 1), iy1 = clampi(y0 + 1, 0, h - 1);
  const float* p00 = img + (size_t(iy0) * size_t(w) + size_t(ix0)) * C;
  const float* p01 = img + (size_t(iy0) * size_t(w) + size_t(ix1)) * C;
  const float* p10 = img + (size_t(iy1) * size_t(w) + size_t(ix0)) * C;
  const float* p11 = img + (size_t(iy1) * size_t(w) + size_t(ix1)) * C;
  for (int c = 0; c < C; ++c)
    out[c] = (1 - ty) * ((1 - tx) * p00[c] + tx * p01[c]) + ty * ((1 - tx) * p10[c] + tx * p11[c]);
}

// Catmull-Rom of an RGB image (interleaved, one float of padding after the last pixel: each
// tap is one 4-float load, the fourth lane is junk). kFootprint: the result clamped per
// channel to the range of the four central taps (the bilinear footprint), so the filter's
// negative lobes cannot overshoot what the image holds there (the history's form).
template <bool kFootprint = false>
static inline __m128 sample_catmull_rom3(const float* img, int w, int h, float x, float y) {
  const float xf = x - 0.5f, yf = y - 0.5f;
  const int x1 = floor_int(xf), y1 = floor_int(yf);
  float wx[4], wy[4];
  catmull_rom(xf - float(x1), wx);
  catmull_rom(yf - float(y1), wy);
  int ix[4], iy[4];
  if (x1 >= 1 && x1 + 2 < w) {
    for (int i = 0; i < 4; ++i) ix[i] = x1 + i - 1;
  } else {
    for (int i = 0; i < 4; ++i) ix[i] = clampi(x1 + i - 1, 0, w - 1);
  }
  if (y1 >= 1 && y1 + 2 < h) {
    for (int i = 0; i < 4; ++i) iy[i] = y1 + i - 1;
  } else {
    for (int i = 0; i < 4; ++i) iy[i] = clampi(y1 + i - 1, 0, h - 1);
  }
  __m128 acc = _mm_setzero_ps();
  __m128 lo = _mm_set1_ps(3e38f), hi = _mm_set1_ps(-3e38f);
  for (int j = 0; j < 4; ++j) {
    const float* row = img + size_t(iy[j]) * size_t(w) * 3;
    __m128 t[4];
    for (int i = 0; i < 4; ++i) t[i] = _mm_loadu_ps(row + size_t(ix[i]) * 3);
    __m128 r = _mm_mul_ps(_mm_set1_ps(wx[0]), t[0]);
    for (int i = 1; i < 4; ++i) r = _mm_add_ps(r, _mm_mul_ps(_mm_set1_ps(wx[i]), t[i]));
    acc = _mm_add_ps(acc, _mm_mul_ps(_mm_set1_ps(wy[j]), r));
    if (kFootprint && (j == 1 || j == 2)) {
      lo = _mm_min_ps(lo, _mm_min_ps(t[1], t[2]));
      hi = _mm_max_ps(hi, _mm_max_ps(t[1], t[2]));
    }
  }
  if (kFootprint) acc = _mm_min_ps(_mm_max_ps(acc, lo), hi);
  return acc;
}

static inline void store3(float* dst, __m128 v) {
  alignas(16) float t[4];
  _mm_store_ps(t, v);
  dst[0] = t[0], dst[1] = t[1], dst[2] = t[2];
}
