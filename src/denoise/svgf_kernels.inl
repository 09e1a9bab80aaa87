// SVGF's hot loops (svgf.h), included by kernels_<isa>.cpp after kernels.inl (exp_neg, the
// vector helpers of simd.inl, FlushDenormals: the weights' tails, e.g. max(0, n.n')^128, underflow
// into denormals).
//
// The a-trous pass runs pixel by pixel with all 25 taps unrolled and the sums in registers,
// vectorised across the pixels of a row's interior. A tap outside the image weighs 0 (its
// row or column clamped to a valid one), which adds exactly nothing: the same sums as
// skipping it, in the scalar definition's tap order. The variance estimate and the blur
// instead cut rows into segments of kSeg pixels with taps as the outer loop, accumulating
// into small arrays (a tap visits only the pixels for which it lies inside the image).

static constexpr int kSeg = 256;
static constexpr float kSvgfB3[5] = {1.0f / 16, 1.0f / 4, 3.0f / 8, 1.0f / 4, 1.0f / 16};

struct SvgfTaps {
  long off[25];          // index offsets from the pixel
  float h[25];           // B3 x B3, 0 for a tap outside the image
  float dx[25], dy[25];  // the tap's offset in pixels (the depth gradient's prediction)
};

// Pixels p .. p + width(T) - 1 of an SVGF pass over the taps; kClass: the black-flag test
// (rows whose taps read no black pixel skip it: every flag is 0 there).
template <class T, bool kClass>
static inline void svgf_pixels(const SvgfPass& a, size_t p, const SvgfTaps& taps) {
  const T zero = T{} + 0.0f, one = T{} + 1.0f;
  const T l = ld<T>(a.lum + p), il = ld<T>(a.inv_l + p), z = ld<T>(a.z + p);
  const T gx = ld<T>(a.gx + p), gy = ld<T>(a.gy + p);
  const T n0 = ld<T>(a.n[0] + p), n1 = ld<T>(a.n[1] + p), n2 = ld<T>(a.n[2] + p);
  const T kp = kClass ? ld<T>(a.black + p) : zero;
  const T zc = 1e-3f * vmax(z, zero + kMinDepth);
  const T floor = (n0 == zero) & (n1 == zero) & (n2 == zero) ? one : zero;
  T a0 = zero, a1 = zero, a2 = zero, ws = zero, va = zero;
  for (int t = 0; t < 25; ++t) {
    const size_t q = size_t(long(p) + taps.off[t]);
    const T wl = vabs(l - ld<T>(a.lum + q)) * il;
    const T pred = vabs(gx * taps.dx[t] + gy * taps.dy[t]);
    const T wz = vabs(z - ld<T>(a.z + q)) / (a.sigma_z * pred + zc);
    T c = vmax(n0 * ld<T>(a.n[0] + q) + n1 * ld<T>(a.n[1] + q) + n2 * ld<T>(a.n[2] + q), zero);
    c *= c, c *= c, c *= c, c *= c, c *= c, c *= c, c *= c;  // ^128
    c = vmax(c, floor);                                      // 1 where there is no normal
    T w = taps.h[t] * (c * vexp_neg(zero - (wl + wz)));
    if constexpr (kClass) w = kp == ld<T>(a.black + q) ? w : zero;  // radiance, irradiance
    a0 += w * ld<T>(a.x[0] + q);
    a1 += w * ld<T>(a.x[1] + q);
    a2 += w * ld<T>(a.x[2] + q);
    ws += w;
    va += w * w * ld<T>(a.var + q);
  }
  const auto any = ws > zero;
  const T inv = one / (any ? ws : one);
  st(a.out[0] + p, any ? a0 * inv : ld<T>(a.x[0] + p));
  st(a.out[1] + p, any ? a1 * inv : ld<T>(a.x[1] + p));
  st(a.out[2] + p, any ? a2 * inv : ld<T>(a.x[2] + p));
  st(a.var_out + p, any ? va * (inv * inv) : ld<T>(a.var + p));
}

template <bool kClass>
static void svgf_span(const SvgfPass& a, size_t row, int i0, int i1, const SvgfTaps& taps) {
  int i = i0;
  for (; i + kLanes <= i1; i += kLanes) svgf_pixels<vfloat, kClass>(a, row + size_t(i), taps);
  for (; i < i1; ++i) svgf_pixels<float, kClass>(a, row + size_t(i), taps);
}

static void svgf_span(const SvgfPass& a, size_t row, int i0, int i1, const SvgfTaps& taps,
                      bool cls) {
  cls ? svgf_span<true>(a, row, i0, i1, taps) : svgf_span<false>(a, row, i0, i1, taps);
}

static void svgf_pass_rows(const SvgfPass& a, int y0, int y1) {
  const FlushDenormals flush;
  const int W = a.width, H = a.height, d = a.dilation;
  for (int y = y0; y < y1; ++y) {
    const size_t row = size_t(y) * size_t(W);
    SvgfTaps taps;
    bool cls = false;  // a black pixel in a row the taps read
    for (int j = -2, t = 0; j <= 2; ++j) {
      const int qy = y + j * d;
      const bool in = qy >= 0 && qy < H;
      cls |= in && a.black_rows[qy] != 0;
      for (int i = -2; i <= 2; ++i, ++t) {
        taps.off[t] = in ? long(j * d) * long(W) + long(i * d) : long(i * d);
        taps.h[t] = in ? kSvgfB3[j + 2] * kSvgfB3[i + 2] : 0.0f;
        taps.dx[t] = float(i * d), taps.dy[t] = float(j * d);
      }
    }
    const int i0 = std::min(2 * d, W), i1 = std::max(W - 2 * d, i0);
    auto border = [&](int x) {  // columns outside the image weigh 0, read the pixel's own
      SvgfTaps c = taps;
      for (int t = 0; t < 25; ++t) {
        const int qx = x + int(c.dx[t]);
        if (qx < 0 || qx >= W) c.off[t] -= long(c.dx[t]), c.h[t] = 0.0f;
      }
      svgf_span(a, row, x, x + 1, c, cls);
    };
    for (int x = 0; x < i0; ++x) border(x);
    svgf_span(a, row, i0, i1, taps, cls);
    for (int x = i1; x < W; ++x) border(x);
  }
}

static inline void svgf_variance_tap(int n, bool centre, const float* __restrict Z,
                                     const float* __restrict N0, const float* __restrict N1,
                                     const float* __restrict N2, const float* __restrict Zq,
                                     const float* __restrict N0q, const float* __restrict N1q,
                                     const float* __restrict N2q, const float* __restrict M1q,
                                     const float* __restrict M2q, float* __restrict S1,
                                     float* __restrict S2, float* __restrict WS) {
  const float add = centre ? 1.0f : 0.0f;
  // Through for_lanes: GCC left this loop scalar under AVX2 and SSE2 (the exp's selects),
  // and a sequence's first three frames run it on every pixel (210-330 ms at 720p).
  for_lanes(n, [&](auto tag, int k) {
    using T = decltype(tag);
    const T zero = T{} + 0.0f, zp = ld<T>(Z + k);
    const T rel = vabs(zp - ld<T>(Zq + k)) / (zp > kMinDepth ? zp : zero + kMinDepth);
    T c = ld<T>(N0 + k) * ld<T>(N0q + k) + ld<T>(N1 + k) * ld<T>(N1q + k) +
          ld<T>(N2 + k) * ld<T>(N2q + k);
    c = c > zero ? c : zero;
    c *= c, c *= c, c *= c, c *= c, c *= c;  // ^32
    const T w = vexp_neg(zero - rel / 0.05f) * c + add;
    st(S1 + k, ld<T>(S1 + k) + w * ld<T>(M1q + k));
    st(S2 + k, ld<T>(S2 + k) + w * ld<T>(M2q + k));
    st(WS + k, ld<T>(WS + k) + w);
  });
}

static void svgf_variance_rows(const SvgfVariance& a, int y0, int y1) {
  const FlushDenormals flush;
  const int W = a.width, H = a.height;
  alignas(64) float S1[kSeg], S2[kSeg], WS[kSeg];
  for (int y = y0; y < y1; ++y) {
    const size_t row = size_t(y) * size_t(W);
    for (int s0 = 0; s0 < W; s0 += kSeg) {
      const int s1 = s0 + kSeg < W ? s0 + kSeg : W;
      bool need = false;
      for (int k = s0; k < s1; ++k) need |= a.len[row + size_t(k)] < 4.0f;
      if (!need) {
        for (int k = s0; k < s1; ++k) a.out[row + size_t(k)] = a.var[row + size_t(k)];
        continue;
      }
      for (int k = 0; k < kSeg; ++k) S1[k] = S2[k] = WS[k] = 0.0f;
      for (int j = -3; j <= 3; ++j) {
        const int qy = y + j;
        if (qy < 0 || qy >= H) continue;
        for (int i = -3; i <= 3; ++i) {
          const int b = s0 > -i ? s0 : -i, e = s1 < W - i ? s1 : W - i;
          if (b >= e) continue;
          const size_t p = row + size_t(b);
          const size_t q = size_t(long(p) + (long(qy) - long(y)) * long(W) + i);
          const int o = b - s0;
          svgf_variance_tap(e - b, i == 0 && j == 0, a.z + p, a.n[0] + p, a.n[1] + p, a.n[2] + p,
                            a.z + q, a.n[0] + q, a.n[1] + q, a.n[2] + q, a.m1 + q, a.m2 + q, S1 + o,
                            S2 + o, WS + o);
        }
      }
      for (int k = 0; k < s1 - s0; ++k) {
        const size_t p = row + size_t(s0 + k);
        const float m = S1[k] / WS[k], v = S2[k] / WS[k] - m * m;
        a.out[p] = a.len[p] < 4.0f ? (v > 0.0f ? v : 0.0f) * 4.0f / a.len[p] : a.var[p];
      }
    }
  }
}

static void svgf_blur_rows(const SvgfBlur& a, int y0, int y1) {
  const FlushDenormals flush;
  const int W = a.width, H = a.height;
  alignas(64) float S[kSeg], WS[kSeg];
  for (int y = y0; y < y1; ++y) {
    const size_t row = size_t(y) * size_t(W);
    for (int s0 = 0; s0 < W; s0 += kSeg) {
      const int s1 = s0 + kSeg < W ? s0 + kSeg : W;
      for (int k = 0; k < kSeg; ++k) S[k] = WS[k] = 0.0f;
      for (int j = -1; j <= 1; ++j) {
        const int qy = y + j;
        if (qy < 0 || qy >= H) continue;
        for (int i = -1; i <= 1; ++i) {
          const int b = s0 > -i ? s0 : -i, e = s1 < W - i ? s1 : W - i;
          const float w = (j == 0 ? 0.5f : 0.25f) * (i == 0 ? 0.5f : 0.25f);
          const float* __restrict v = a.var + long(row) + (long(qy) - long(y)) * long(W) + i;
          float* __restrict s = S - s0;
          float* __restrict ws = WS - s0;
          for (int k = b; k < e; ++k) s[k] += w * v[k], ws[k] += w;
        }
      }
      float* __restrict out = a.inv_l + row;
      for (int k = 0; k < s1 - s0; ++k)
        out[s0 + k] = 1.0f / (a.sigma_l * std::sqrt(S[k] / WS[k]) + 1e-4f);
    }
  }
}

// SVGF's temporal step for the pixels [0, W) of row y, branch-free: a bilinear tap that fails
// the consistency test (outside the image, depth off by > 10 %, normals > ~25 degrees apart,
// another black flag) weighs 0 and reads a clamped pixel, which adds exactly nothing: the scalar
// definition's sums.
static void svgf_temporal_row(int y, int W, int H, const float* __restrict X0,
                              const float* __restrict X1, const float* __restrict X2,
                              const float* __restrict Z, const float* __restrict N0,
                              const float* __restrict N1, const float* __restrict N2,
                              const float* __restrict MX, const float* __restrict MY,
                              const float* __restrict K, const float* const* __restrict hist,
                              float* __restrict A0, float* __restrict A1, float* __restrict A2,
                              float* __restrict M1, float* __restrict M2, float* __restrict LEN,
                              float* __restrict VAR) {
  const float* __restrict H0 = hist[0], * __restrict H1 = hist[1], * __restrict H2 = hist[2];
  const float* __restrict H3 = hist[3], * __restrict H4 = hist[4], * __restrict H5 = hist[5];
  const float* __restrict HZ = hist[6], * __restrict HN0 = hist[7], * __restrict HN1 = hist[8], * __restrict HN2 = hist[9];
  const float* __restrict HK = hist[10];
  const size_t row = size_t(y) * size_t(W);
  for (int i = 0; i < W; ++i) {
    const size_t p = row + size_t(i);
    const float x0 = X0[p], x1 = X1[p], x2 = X2[p];
    const float l = 0.2126f * x0 + 0.7152f * x1 + 0.0722f * x2;
    const float px = float(i) + MX[p], py = float(y) + MY[p];
    const float flx = std::floor(px), fly = std::floor(py);
    const int xi = int(flx), yi = int(fly);
    const float fx = px - flx, fy = py - fly;
    const float z = Z[p], n0 = N0[p], n1 = N1[p], n2 = N2[p];
    const bool no_normal = (n0 == 0.0f) & (n1 == 0.0f) & (n2 == 0.0f);
    const float zmax = 0.1f * std::max(z, kMinDepth), k = K[p];
    float h0 = 0, h1 = 0, h2 = 0, h3 = 0, h4 = 0, hl = 0, wsum = 0;
    auto tap = [&](int sx, int sy, float w) {
      const bool in = (sx >= 0) & (sy >= 0) & (sx < W) & (sy < H);
      const size_t q = in ? size_t(sy) * size_t(W) + size_t(sx) : p;
      const float nd = n0 * HN0[q] + n1 * HN1[q] + n2 * HN2[q];
      const bool ok =
          in & !(std::fabs(HZ[q] - z) > zmax) & (no_normal | (nd > 0.9f)) & (HK[q] == k);
      w = ok ? w : 0.0f;
      h0 += w * H0[q], h1 += w * H1[q], h2 += w * H2[q], h3 += w * H3[q], h4 += w * H4[q];
      hl += w * H5[q];
      wsum += w;
    };
    tap(xi, yi, (1 - fx) * (1 - fy));
    tap(xi + 1, yi, fx * (1 - fy));
    tap(xi, yi + 1, (1 - fx) * fy);
    tap(xi + 1, yi + 1, fx * fy);
    const bool have = wsum > 1e-3f;
    const float inv = have ? wsum : 1.0f;
    h0 /= inv, h1 /= inv, h2 /= inv, h3 /= inv, h4 /= inv;
    hl = have ? hl / inv : 0.0f;
    const float n = std::min(hl, 254.0f) + 1.0f;
    const float a = std::max(1.0f / n, 0.2f);
    const bool keep = hl > 0;
    A0[p] = keep ? h0 + a * (x0 - h0) : x0;
    A1[p] = keep ? h1 + a * (x1 - h1) : x1;
    A2[p] = keep ? h2 + a * (x2 - h2) : x2;
    const float m1 = keep ? h3 + a * (l - h3) : l;
    const float m2 = keep ? h4 + a * (l * l - h4) : l * l;
    M1[p] = m1, M2[p] = m2, LEN[p] = n;
    VAR[p] = std::max(0.0f, m2 - m1 * m1);
  }
}

static void svgf_temporal_rows(const SvgfTemporal& a, int y0, int y1) {
  for (int y = y0; y < y1; ++y)
    svgf_temporal_row(y, a.width, a.height, a.x[0], a.x[1], a.x[2], a.z, a.n[0], a.n[1], a.n[2],
                      a.mx, a.my, a.black, a.hist, a.acc[0], a.acc[1], a.acc[2], a.m1, a.m2, a.len,
                      a.var);
}
