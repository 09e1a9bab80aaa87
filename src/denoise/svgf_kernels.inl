// SVGF's hot loops (svgf.h), included by kernels_<isa>.cpp after kernels.inl (the vector
// helpers of core/simd/lanes.inl, FlushDenormals: the weights' tails underflow into denormals).
//
// The a-trous pass runs pixel by pixel with its 3x3 taps unrolled and the sums in registers,
// vectorised across the pixels of a row's interior, every edge stop in one exp per tap; the
// variance blur of the luminance edge stop is computed there too, from the same plane, so no pass
// writes it out. A tap outside the image weighs 0 (its row or column clamped to a valid one), which
// adds exactly nothing: the same sums as skipping it. The depth edge stop's denominator depends on
// the tap only through |gx dx + gy dy|, which opposite taps share: four reciprocals per pixel
// instead of eight divisions. The variance estimate instead cuts rows into segments of kSeg pixels
// with taps as the outer loop, accumulating into small arrays (a tap visits only the pixels for
// which it lies inside the image).

static constexpr int kSeg = 32;
static constexpr float kSvgfB1[3] = {0.25f, 0.5f, 0.25f};  // the variance blur
// The normal edge stop exp(sigma_n (n.n' - 1)), sigma_n = 128, in base 2.
static constexpr float kSigmaN2 = 128.0f * kLog2e;

struct SvgfTaps {
  long off[9];      // index offsets from the pixel (row-major 3x3, the centre at 4)
  float lh[9];      // log2 of the tap's weight (0, the box; -inf outside the image) - kSigmaN2
  long boff[9];     // the variance blur's offsets (+-1 pixel)
  float bw[9];      // its weights, 0 outside the image
  float bnorm = 1;  // 1 / sum of bw

  // svgf_pixels' view: tap t's and blur tap b's weights and values for the pixels at p.
  float lh_of(int t) const { return lh[t]; }
  float bw_of(int b) const { return bw[b]; }
  float bnorm_of() const { return bnorm; }
  template <class T>
  T tap(const float* plane, int t, size_t p) const {
    return ld<T>(plane + size_t(long(p) + off[t]));
  }
  template <class T>
  T blur(const float* plane, int b, size_t p) const {
    return ld<T>(plane + size_t(long(p) + boff[b]));
  }
};

// A vector of pixels at the image's left or right edge (columns x .. x + kLanes - 1, all
// inside the row): per lane, a tap or blur tap whose column leaves the image weighs 0 (as in
// SvgfTaps for one pixel) and reads the row's edge pixel instead (any finite value adds 0).
struct SvgfEdgeTaps {
  vfloat lh[9], bw[9], bnorm;
  long trow[9], brow[9];  // the taps' rows (index of their first pixel)
  int dx[9], bdx[9], x = 0, width = 0;

  // From the row's taps (their rows already chosen) for the vector at column x.
  SvgfEdgeTaps(const SvgfTaps& row_taps, long row, int x0, int w, int d) : x(x0), width(w) {
    const vint col = lane_iota(vint{}) + x0;
    vfloat sum = vfloat{};
    for (int t = 0; t < 9; ++t) {
      const int i = t % 3 - 1;
      dx[t] = i * d, bdx[t] = i;
      trow[t] = row + row_taps.off[t] - dx[t], brow[t] = row + row_taps.boff[t] - bdx[t];
      const vint in = (col + dx[t] >= 0) & (col + dx[t] < w);
      const vint bin = (col + bdx[t] >= 0) & (col + bdx[t] < w);
      lh[t] = in ? vfloat{} + row_taps.lh[t] : vfloat{} - INFINITY;
      bw[t] = bin ? vfloat{} + row_taps.bw[t] : vfloat{};
      sum += bw[t];
    }
    bnorm = 1.0f / sum;
  }
  vfloat lh_of(int t) const { return lh[t]; }
  vfloat bw_of(int b) const { return bw[b]; }
  vfloat bnorm_of() const { return bnorm; }
  template <class T>
  T tap(const float* plane, int t, size_t) const {
    return ld_clamped(T{}, plane + trow[t], x + dx[t], width);
  }
  template <class T>
  T blur(const float* plane, int b, size_t) const {
    return ld_clamped(T{}, plane + brow[b], x + bdx[b], width);
  }
};

// Which of |gx|, |gy|, |gx + gy|, |gx - gy| (times the dilation) predicts tap t's depth change.
static constexpr int kSvgfSlope[9] = {2, 1, 3, 0, 0, 0, 3, 1, 2};

// Pixels p .. p + width(T) - 1 of an SVGF pass over the taps; kClass: the black-flag test
// (rows whose taps read no black pixel skip it: every flag is 0 there).
template <class T, bool kClass, class Taps>
static inline void svgf_pixels(const SvgfPass& a, size_t p, const Taps& taps) {
  const T zero = T{} + 0.0f, one = T{} + 1.0f;
  T g = zero;  // the 3x3 Gaussian blur of the variance
  for (int b = 0; b < 9; ++b) g += taps.bw_of(b) * taps.template blur<T>(a.var, b, p);
  const T il = kLog2e / (a.sigma_l * vsqrt(g * taps.bnorm_of()) + 1e-4f);
  const T l = ld<T>(a.lum + p), z = ld<T>(a.z + p);
  const T gx = ld<T>(a.gx + p), gy = ld<T>(a.gy + p);
  const T zc = 1e-3f * vmax(z, zero + kMinDepth), sz = zero + a.sigma_z * float(a.dilation);
  const T rden[4] = {kLog2e / (sz * vabs(gx) + zc), kLog2e / (sz * vabs(gy) + zc),
                     kLog2e / (sz * vabs(gx + gy) + zc), kLog2e / (sz * vabs(gx - gy) + zc)};
  const T n0 = ld<T>(a.n[0] + p), n1 = ld<T>(a.n[1] + p), n2 = ld<T>(a.n[2] + p);
  const T kp = kClass ? ld<T>(a.black + p) : zero;
  const T floor = (n0 == zero) & (n1 == zero) & (n2 == zero) ? one : zero;
  // The centre: no luminance or depth difference, its own class.
  T ws = vexp2(kSigmaN2 * vmax(n0 * n0 + n1 * n1 + n2 * n2, floor) - kSigmaN2);
  T a0 = ws * ld<T>(a.x[0] + p), a1 = ws * ld<T>(a.x[1] + p), a2 = ws * ld<T>(a.x[2] + p);
  T va = ws * ws * ld<T>(a.var + p);
#pragma GCC unroll 9
  for (int t = 0; t < 9; ++t) {
    if (t == 4) continue;
    const auto at = [&](const float* plane) { return taps.template tap<T>(plane, t, p); };
    const T wl = vabs(l - at(a.lum)) * il;
    const T wz = vabs(z - at(a.z)) * rden[kSvgfSlope[t]];
    const T c = vmax(n0 * at(a.n[0]) + n1 * at(a.n[1]) + n2 * at(a.n[2]), floor);
    T w = vexp2(kSigmaN2 * c + taps.lh_of(t) - wl - wz);     // lh holds the normal stop's -kSigmaN2
    if constexpr (kClass) w = kp == at(a.black) ? w : zero;  // radiance, irradiance
    a0 += w * at(a.x[0]);
    a1 += w * at(a.x[1]);
    a2 += w * at(a.x[2]);
    ws += w;
    va += w * w * at(a.var);
  }
  const auto any = ws > zero;
  const T inv = one / (any ? ws : one);
  const T o0 = any ? a0 * inv : ld<T>(a.x[0] + p), o1 = any ? a1 * inv : ld<T>(a.x[1] + p),
          o2 = any ? a2 * inv : ld<T>(a.x[2] + p);
  st(a.out[0] + p, o0), st(a.out[1] + p, o1), st(a.out[2] + p, o2);
  st(a.lum_out + p, 0.2126f * o0 + 0.7152f * o1 + 0.0722f * o2);
  st(a.var_out + p, any ? va * (inv * inv) : ld<T>(a.var + p));
}

// Row `row`, kLanes pixels at a time: where every tap of the lanes lies inside the image
// (columns [i0, i1)) with the row's taps, at the edges with each lane's (SvgfEdgeTaps); the
// last columns by a vector ending at the row's end, which recomputes some of the one before
// (the same values: a pass reads other planes than it writes). Rows narrower than a vector:
// pixel by pixel (border_px).
template <bool kClass, class Border>
static void svgf_row(const SvgfPass& a, size_t row, int i0, int i1, const SvgfTaps& taps,
                     Border&& border_px) {
  const int w = a.width;
  if (w < kLanes) {
    for (int x = 0; x < w; ++x) border_px(x);
    return;
  }
  const auto at = [&](int x) {
    if (x >= i0 && x + kLanes <= i1)
      svgf_pixels<vfloat, kClass>(a, row + size_t(x), taps);
    else
      svgf_pixels<vfloat, kClass>(a, row + size_t(x),
                                  SvgfEdgeTaps(taps, long(row), x, w, a.dilation));
  };
  int x = 0;
  for (; x + kLanes <= w; x += kLanes) at(x);
  if (x < w) at(w - kLanes);
}

static void svgf_pass_rows(const SvgfPass& a, int y0, int y1) {
  const FlushDenormals flush;
  const int W = a.width, H = a.height, d = a.dilation;
  for (int y = y0; y < y1; ++y) {
    const size_t row = size_t(y) * size_t(W);
    SvgfTaps taps;
    bool cls = false;  // a black pixel in a row the taps read
    float bsum = 0;
    for (int j = -1, t = 0; j <= 1; ++j) {
      const int qy = y + j * d, by = y + j;
      const bool in = qy >= 0 && qy < H, bin = by >= 0 && by < H;
      cls |= in && a.black_rows[qy] != 0;
      for (int i = -1; i <= 1; ++i, ++t) {
        taps.off[t] = in ? long(j * d) * long(W) + long(i * d) : long(i * d);
        taps.lh[t] = in ? -kSigmaN2 : -INFINITY;
        taps.boff[t] = bin ? long(j) * long(W) + long(i) : long(i);
        taps.bw[t] = bin ? kSvgfB1[j + 1] * kSvgfB1[i + 1] : 0.0f;
        bsum += taps.bw[t];
      }
    }
    taps.bnorm = 1.0f / bsum;
    const int i0 = std::min(d, W), i1 = std::max(W - d, i0);
    auto border = [&](int x) {  // columns outside the image weigh 0, read the pixel's own
      SvgfTaps c = taps;
      float s = 0;
      for (int t = 0; t < 9; ++t) {
        const int i = t % 3 - 1;
        if (x + i * d < 0 || x + i * d >= W) c.off[t] -= long(i * d), c.lh[t] = -INFINITY;
        if (x + i < 0 || x + i >= W) c.boff[t] -= long(i), c.bw[t] = 0.0f;
        s += c.bw[t];
      }
      c.bnorm = 1.0f / s;
      cls ? svgf_pixels<float, true>(a, row + size_t(x), c)
          : svgf_pixels<float, false>(a, row + size_t(x), c);
    };
    cls ? svgf_row<true>(a, row, i0, i1, taps, border)
        : svgf_row<false>(a, row, i0, i1, taps, border);
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

// SVGF's temporal step for one pixel (T = float) or kLanes pixels in a row (T = vfloat) at p,
// branch-free: fetch(plane, k) reads the history at the four bilinear taps and wb[k] are their
// weights (0 for a tap outside the image, whose reads are then a valid pixel's). A tap that
// fails the consistency test (depth off by > 10 %, normals > ~25 degrees apart, another black
// flag) weighs 0 too, which adds exactly nothing: the scalar definition's sums.
template <class T, class Fetch>
static inline void svgf_temporal_px(const SvgfTemporal& a, size_t p, const T wb[4], Fetch&& fetch) {
  const T zero = T{} + 0.0f, one = T{} + 1.0f;
  const T x0 = ld<T>(a.x[0] + p), x1 = ld<T>(a.x[1] + p), x2 = ld<T>(a.x[2] + p);
  const T l = 0.2126f * x0 + 0.7152f * x1 + 0.0722f * x2;
  const T z = ld<T>(a.z + p), n0 = ld<T>(a.n[0] + p), n1 = ld<T>(a.n[1] + p),
          n2 = ld<T>(a.n[2] + p), k = ld<T>(a.black + p);
  const auto no_normal = (n0 == zero) & (n1 == zero) & (n2 == zero);
  const T zmax = 0.1f * vmax(z, zero + kMinDepth);
  const float* const* h = a.hist;
  T h0 = zero, h1 = zero, h2 = zero, h3 = zero, h4 = zero, hl = zero, wsum = zero;
  for (int t = 0; t < 4; ++t) {
    const T nd = n0 * fetch(h[7], t) + n1 * fetch(h[8], t) + n2 * fetch(h[9], t);
    T w = (no_normal | (nd > 0.9f)) & (fetch(h[10], t) == k) ? wb[t] : zero;
    w = vabs(fetch(h[6], t) - z) > zmax ? zero : w;
    h0 += w * fetch(h[0], t), h1 += w * fetch(h[1], t), h2 += w * fetch(h[2], t);
    h3 += w * fetch(h[3], t), h4 += w * fetch(h[4], t), hl += w * fetch(h[5], t);
    wsum += w;
  }
  const auto have = wsum > 1e-3f;
  const T inv = have ? wsum : one;
  h0 /= inv, h1 /= inv, h2 /= inv, h3 /= inv, h4 /= inv;
  hl = have ? hl / inv : zero;
  const T n = (hl < 254.0f ? hl : zero + 254.0f) + 1.0f;
  const T al = vmax(one / n, zero + 0.2f);
  const auto keep = hl > zero;
  st(a.acc[0] + p, keep ? h0 + al * (x0 - h0) : x0);
  st(a.acc[1] + p, keep ? h1 + al * (x1 - h1) : x1);
  st(a.acc[2] + p, keep ? h2 + al * (x2 - h2) : x2);
  const T m1 = keep ? h3 + al * (l - h3) : l;
  const T m2 = keep ? h4 + al * (l * l - h4) : l * l;
  st(a.m1 + p, m1), st(a.m2 + p, m2), st(a.len + p, n);
  const T v = m2 - m1 * m1;
  st(a.var + p, v > zero ? v : zero);
}

// Row y: kLanes pixels at a time (where their taps are kLanes consecutive pixels of the
// history, the same whole-pixel motion across the lanes, with plain loads; elsewhere by
// gathers), the row's tail pixel by pixel.
static void svgf_temporal_rows(const SvgfTemporal& a, int y0, int y1) {
  const int W = a.width, H = a.height;
  for (int y = y0; y < y1; ++y) {
    const size_t row = size_t(y) * size_t(W);
    int i = 0;
    for (; i + kLanes <= W; i += kLanes) {
      const size_t p = row + size_t(i);
      const vfloat column = vindex(vfloat{}, i);
      vfloat px = column + ld<vfloat>(a.mx + p), py = float(y) + ld<vfloat>(a.my + p);
      // Within int's range (NaN is not): elsewhere far outside the image.
      const vint ok = (vabs(px) < 1e9f) & (vabs(py) < 1e9f);
      px = ok ? px : vfloat{} - 1e9f, py = ok ? py : vfloat{} - 1e9f;
      const vint xi = vfloor(px), yi = vfloor(py);
      const vfloat fx = px - vfloat_of(xi), fy = py - vfloat_of(yi);
      const int x0 = xi[0], yy = yi[0];
      const bool uniform = x0 >= 0 && x0 + kLanes < W && yy >= 0 && yy + 1 < H &&
                           all_of((xi == x0 + lane_iota(xi)) & (yi == yy));
      vfloat wb[4] = {(1.0f - fx) * (1.0f - fy), fx * (1.0f - fy), (1.0f - fx) * fy, fx * fy};
      if (uniform) {
        const size_t s = size_t(yy) * size_t(W) + size_t(x0);
        const size_t q[4] = {s, s + 1, s + size_t(W), s + size_t(W) + 1};
        svgf_temporal_px<vfloat>(a, p, wb,
                                 [&](const float* h, int t) { return ld<vfloat>(h + q[t]); });
        continue;
      }
#if defined(__AVX512F__)
      // A moving camera: the lanes' taps differ but lie in one or two rows and within 32
      // columns (every tap inside the image). Each tap is then picked from two loaded vectors
      // of its row by a permute (and the row by a blend) instead of a gather: the same values.
      const int xmin = lane_min(xi), xmax = lane_max(xi), ymin = lane_min(yi), ymax = lane_max(yi);
      if (xmin >= 0 && xmax - xmin <= 30 && xmin + 32 <= W && ymin >= 0 && ymax - ymin <= 1 &&
          ymax + 1 < H) {
        const size_t s = size_t(ymin) * size_t(W) + size_t(xmin);
        const vint ix[2] = {xi - xmin, xi + 1 - xmin};
        const vint lower = yi != ymin;  // the lanes whose taps start a row further down
        auto pick = [&](const float* r, vint i) {
          return perm2(ld<vfloat>(r), ld<vfloat>(r + kLanes), i);
        };
        if (ymax == ymin) {
          svgf_temporal_px<vfloat>(a, p, wb, [&](const float* h, int t) {
            return pick(h + s + size_t(t >> 1) * size_t(W), ix[t & 1]);
          });
        } else {
          svgf_temporal_px<vfloat>(a, p, wb, [&](const float* h, int t) {
            const float* r = h + s + size_t(t >> 1) * size_t(W);
            return lower ? pick(r + W, ix[t & 1]) : pick(r, ix[t & 1]);
          });
        }
        continue;
      }
#endif
      vint idx[4];
      const vint own = vtrunc(column) + y * W;  // the pixels themselves
      for (int t = 0; t < 4; ++t) {
        const vint sx = xi + (t & 1), sy = yi + (t >> 1);
        const vint in = (sx >= 0) & (sy >= 0) & (sx < W) & (sy < H);
        idx[t] = in ? sy * W + sx : own;
        wb[t] = in ? wb[t] : vfloat{};
      }
      svgf_temporal_px<vfloat>(a, p, wb, [&](const float* h, int t) { return vgather(h, idx[t]); });
    }
    for (; i < W; ++i) {  // the tail: one pixel at a time
      const size_t p = row + size_t(i);
      float px = float(i) + a.mx[p], py = float(y) + a.my[p];
      if (!(std::fabs(px) < 1e9f && std::fabs(py) < 1e9f)) px = py = -1e9f;  // as above
      const float flx = std::floor(px), fly = std::floor(py);
      const int xi = int(flx), yi = int(fly);
      const float fx = px - flx, fy = py - fly;
      size_t q[4];
      float wb[4];
      for (int t = 0; t < 4; ++t) {
        const int sx = xi + (t & 1), sy = yi + (t >> 1);
        const bool in = (sx >= 0) & (sy >= 0) & (sx < W) & (sy < H);
        q[t] = in ? size_t(sy) * size_t(W) + size_t(sx) : p;
        wb[t] = in ? ((t & 1) ? fx : 1 - fx) * ((t >> 1) ? fy : 1 - fy) : 0.0f;
      }
      svgf_temporal_px<float>(a, p, wb, [&](const float* h, int t) { return h[q[t]]; });
    }
  }
}

static void svgf_demodulate_rows(const SvgfDemodulate& a, int y0, int y1) {
  const int W = a.width;
  for (int y = y0; y < y1; ++y) {
    const size_t row = size_t(y) * size_t(W);
    const float *a0 = a.albedo[0] + row, *a1 = a.albedo[1] + row, *a2 = a.albedo[2] + row;
    a.black_rows[y] = black_row(W, a0, a1, a2, a.black + row);
    for (int c = 0; c < 3; ++c) {
      const float *col = a.color[c] + row, *alb = a.albedo[c] + row;
      float *d = a.d[c] + row, *x = a.x[c] + row;
      for_lanes(W, [&](auto tag, int i) {
        using T = decltype(tag);
        const T dm = demodulation(ld<T>(a0 + i), ld<T>(a1 + i), ld<T>(a2 + i), ld<T>(alb + i));
        st(d + i, dm), st(x + i, ld<T>(col + i) / dm);
      });
    }
  }
}
