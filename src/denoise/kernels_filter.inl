// Included by kernels.inl (inside namespace kestrel::denoise::KESTREL_ISA_NS, after
// core/simd/lanes.inl): the neural denoiser's a-trous filter, one level's rows (model.py's filter).

// One a-trous level's row: its planes, the two quarter-res parameter rows it lerps (fy the
// weight of the lower one) and the 8 outer taps (the centre weighs exactly 1: every
// difference is 0 and n.n - n.n = 0) as index offsets from the pixel with their spline
// weights. Border pixels get their own copy with offsets clamped per pixel. A tap whose
// demodulation differs from the pixel's (`k`: 1 black, 0 not) weighs 0: radiance and
// irradiance do not mix. Rows whose taps read no black pixel skip that test (kClass false):
// every flag is 0 there, so it is the same function.
struct AtrousRow {
  const float *x0, *x1, *x2, *g0, *g1, *g2, *n0, *n1, *n2, *z, *k;
  const float *sc_top, *sc_bot, *sn_top, *sn_bot, *sz_top, *sz_bot, *beta_top, *beta_bot;
  float *o0, *o1, *o2, *go0, *go1, *go2;  // go*: the next level's guide, or null
  float fy, gy;                           // gy = 1 - fy
  long off[8];
  float lh[8];       // log2 of the tap's spline weight (the centre's 1 left out): -1 or -2
  int w = 0, d = 1;  // the row's width and the level's dilation (for clamped taps)
};

// Tap t's column step (times the dilation), in the taps' order (dy, dx), the centre left out.
static constexpr int kTapDx[8] = {-1, 0, 1, -1, 1, -1, 0, 1};

// Pixels p .. p + width(T) - 1 (column i of the row): the taps, the accumulation and the mix,
// with T = float or vfloat (every operation lane by lane, so both give the same values).
template <class T, bool kGuide, bool kClass, bool kClamp = false>
static inline void atrous_lanes(const AtrousRow& r, size_t p, int i) {
  const T zero = T{} + 0.0f;
  // Tap t's value of a plane: at p + off[t], or (kClamp, vector lanes) at each lane's column
  // clamped to its row (off[t] holds the row's offset plus dx), the pixels a border pixel's
  // taps read (the same addresses as its scalar form).
  const auto tap = [&](const float* plane, int t, size_t q) -> T {
    if constexpr (kClamp) {
      const int dx = kTapDx[t] * r.d;
      return ld_clamped(T{}, plane + (long(q) - i - dx), i + dx, r.w);
    } else {
      return ld<T>(plane + q);
    }
  };
  const T x0 = ld<T>(r.x0 + p), x1 = ld<T>(r.x1 + p), x2 = ld<T>(r.x2 + p);
  const T g0 = ld<T>(r.g0 + p), g1 = ld<T>(r.g1 + p), g2 = ld<T>(r.g2 + p);
  const T n0 = ld<T>(r.n0 + p), n1 = ld<T>(r.n1 + p), n2 = ld<T>(r.n2 + p), z = ld<T>(r.z + p);
  const T kp = kClass ? ld<T>(r.k + p) : zero;
  // The strengths in base 2 (vexp2).
  const T sc = (ld<T>(r.sc_top + i) * r.gy + ld<T>(r.sc_bot + i) * r.fy) * kLog2e;
  const T sn = (ld<T>(r.sn_top + i) * r.gy + ld<T>(r.sn_bot + i) * r.fy) * kLog2e;
  const T sz = (ld<T>(r.sz_top + i) * r.gy + ld<T>(r.sz_bot + i) * r.fy) * kLog2e /
               (z > kMinDepth ? z : zero + kMinDepth);
  const T nn = n0 * n0 + n1 * n1 + n2 * n2;
  T acc0 = x0, acc1 = x1, acc2 = x2, wsum = zero + 1.0f;
#pragma GCC unroll 8
  for (int t = 0; t < 8; ++t) {
    const size_t q = size_t(long(p) + r.off[t]);
    const T d0 = g0 - tap(r.g0, t, q), d1 = g1 - tap(r.g1, t, q), d2 = g2 - tap(r.g2, t, q);
    const T dot = n0 * tap(r.n0, t, q) + n1 * tap(r.n1, t, q) + n2 * tap(r.n2, t, q);
    const T nd0 = nn - dot, nd = nd0 > zero ? nd0 : zero;
    const T dz = vabs(z - tap(r.z, t, q));
    const T e = sc * (d0 * d0 + d1 * d1 + d2 * d2) + sn * nd + sz * dz;
    T wq = vexp2(r.lh[t] - e);
    if constexpr (kClass) wq = kp == tap(r.k, t, q) ? wq : zero;
    acc0 += wq * tap(r.x0, t, q);
    acc1 += wq * tap(r.x1, t, q);
    acc2 += wq * tap(r.x2, t, q);
    wsum += wq;
  }
  const T inv = 1.0f / wsum, beta = ld<T>(r.beta_top + i) * r.gy + ld<T>(r.beta_bot + i) * r.fy;
  const T o0 = x0 + beta * (acc0 * inv - x0), o1 = x1 + beta * (acc1 * inv - x1),
          o2 = x2 + beta * (acc2 * inv - x2);
  st(r.o0 + p, o0), st(r.o1 + p, o1), st(r.o2 + p, o2);
  if constexpr (kGuide) {
    st(r.go0 + p, vlog1p_pos(o0 > zero ? o0 : zero));
    st(r.go1 + p, vlog1p_pos(o1 > zero ? o1 : zero));
    st(r.go2 + p, vlog1p_pos(o2 > zero ? o2 : zero));
  }
}

// Row `row`, kLanes pixels at a time: where every tap of the lanes lies inside the image
// (columns [i0, i1)) with plain loads, elsewhere with each lane's taps clamped; the last
// columns by a vector ending at the row's end, which recomputes some of the one before
// (the same values: the level reads other planes than it writes). Rows narrower than a vector:
// pixel by pixel, taps clamped per pixel (border_px).
template <bool kGuide, bool kClass, class Border>
static void atrous_row(const AtrousRow& r, size_t row, int i0, int i1, Border&& border_px) {
  const int w = r.w;
  if (w < kLanes) {
    for (int i = 0; i < w; ++i) border_px(i);
    return;
  }
  const auto at = [&](int i) {
    if (i >= i0 && i + kLanes <= i1)
      atrous_lanes<vfloat, kGuide, kClass>(r, row + size_t(i), i);
    else
      atrous_lanes<vfloat, kGuide, kClass, true>(r, row + size_t(i), i);
  };
  int i = 0;
  for (; i + kLanes <= w; i += kLanes) at(i);
  if (i < w) at(w - kLanes);
}

template <bool kGuide, bool kClass>
static void atrous_px(const AtrousRow& r, size_t row, int i) {
  atrous_lanes<float, kGuide, kClass>(r, row + size_t(i), i);
}

static void atrous_rows(const AtrousArgs& a, int row0, int row1) {
  const int w = a.width, h = a.height, d = a.dilation;
  AtrousRow r;
  r.x0 = a.x[0], r.x1 = a.x[1], r.x2 = a.x[2], r.g0 = a.g[0], r.g1 = a.g[1], r.g2 = a.g[2];
  r.n0 = a.n[0], r.n1 = a.n[1], r.n2 = a.n[2], r.z = a.z, r.k = a.black;
  r.o0 = a.out[0], r.o1 = a.out[1], r.o2 = a.out[2];
  r.go0 = a.gout[0], r.go1 = a.gout[1], r.go2 = a.gout[2];
  r.w = w, r.d = d;
  for (int y = row0; y < row1; ++y) {
    const size_t row = size_t(y) * size_t(w);
    // Taps in PyTorch's order (dy, dx), centre left out; rows clamped to the image.
    long row_off[3];
    bool cls = false;  // a black pixel in a row the taps read
    for (int ty = -1; ty <= 1; ++ty) {
      int qy = y + ty * d;
      qy = qy < 0 ? 0 : (qy >= h ? h - 1 : qy);
      row_off[ty + 1] = (long(qy) - long(y)) * long(w);
      cls |= a.black_rows[qy] != 0;
    }
    int t = 0;
    for (int ty = -1; ty <= 1; ++ty)
      for (int tx = -1; tx <= 1; ++tx) {
        if (tx == 0 && ty == 0) continue;
        r.off[t] = row_off[ty + 1] + long(tx * d);
        r.lh[t] = ty == 0 || tx == 0 ? -1.0f : -2.0f;  // spline weights 1/2, 1/4
        ++t;
      }
    // The two quarter-res parameter rows this row lerps (upsampled horizontally: w wide).
    const UpTap ty = up_tap(y, a.param_rows, 0.25f);
    r.fy = ty.f, r.gy = 1 - ty.f;
    const size_t top = size_t(ty.i0) * size_t(w), bot = size_t(ty.i1) * size_t(w);
    r.sc_top = a.param[0] + top, r.sc_bot = a.param[0] + bot;
    r.sn_top = a.param[1] + top, r.sn_bot = a.param[1] + bot;
    r.sz_top = a.param[2] + top, r.sz_bot = a.param[2] + bot;
    r.beta_top = a.param[3] + top, r.beta_bot = a.param[3] + bot;
    const int i0 = d < w ? d : w, i1 = w - d > i0 ? w - d : i0;
    auto border = [&](int i) {  // a row narrower than a vector: columns clamped per pixel
      AtrousRow c = r;
      int k = 0;
      for (int ty = -1; ty <= 1; ++ty)
        for (int tx = -1; tx <= 1; ++tx) {
          if (tx == 0 && ty == 0) continue;
          int qx = i + tx * d;
          qx = qx < 0 ? 0 : (qx >= w ? w - 1 : qx);
          c.off[k++] = row_off[ty + 1] + long(qx - i);
        }
      if (r.go0)
        cls ? atrous_px<true, true>(c, row, i) : atrous_px<true, false>(c, row, i);
      else
        cls ? atrous_px<false, true>(c, row, i) : atrous_px<false, false>(c, row, i);
    };
    if (r.go0)
      cls ? atrous_row<true, true>(r, row, i0, i1, border)
          : atrous_row<true, false>(r, row, i0, i1, border);
    else
      cls ? atrous_row<false, true>(r, row, i0, i1, border)
          : atrous_row<false, false>(r, row, i0, i1, border);
  }
}
