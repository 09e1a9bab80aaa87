// The nsrr family's kernel-predicting blend (scripts/upscale/nsrr.py: blend; nsrr_parts.h:
// Blend), compiled per instruction set with the upsampler's other per-pixel stages
// (reconstruct_*.cpp) and written once for T = float and T = vfloat (core/simd/lanes.inl).

// Low-res pixels i (< 0: none) as lookup reads them: the span [lo, hi] of those present and
// the indices with the absent ones inside it. Neighbouring pixels' samples are neighbouring
// low-res pixels where the motion is smooth: one load and a permute instead of a gather where
// they span few.
template <class I>
struct Picks {
  I i, ic;
  int lo, hi;
  explicit Picks(I i_) : i(i_) {
    hi = lane_max(i);
    lo = hi < 0 ? 0 : lane_min(i >= 0 ? i : I{} + hi);
    ic = i >= 0 ? i : I{} + lo;
    if (hi < 0) hi = lo;
  }
};
// y (3 planes of n, padded by kMaxLanes) at the picks, 0 where absent.
template <class T, class I>
static inline void samples_at(const float* y, size_t n, const Picks<I>& p, T v[3]) {
  for (size_t c = 0; c < 3; ++c) {
    const T s = lookup(y + c * n, p.ic, p.lo, p.hi);
    v[c] = p.i >= 0 ? s : T{};
  }
}

// A frame's samples at the output resolution (nsrr.zero_upsample of y and of the presence):
// rows [r0, r1) of the four planes, the image at offset (r, r).
static void zero_upsample_rows(const ZeroUpArgs& a, int r0, int r1) {
  const size_t Wz = size_t(a.W) + 2 * size_t(a.r), plane = Wz * (size_t(a.H) + 2 * size_t(a.r));
  for (int Y = r0; Y < r1; ++Y) {
    const int* at = a.at + size_t(Y) * size_t(a.W);
    float* z = a.z + size_t(Y + a.r) * Wz + size_t(a.r);
    for_lanes(a.W, [&](auto t, int X) {
      using T = decltype(t);
      using I = lanes_int<T>;
      const I i = ldi<I>(at + X);
      const auto ok = i >= 0;
      T v[3];
      samples_at(a.y, a.n, Picks(i), v);
      for (size_t c = 0; c < 3; ++c) st(z + c * plane + size_t(X), v[c]);
      st(z + 3 * plane + size_t(X), ok ? T{} + 1.0f : T{});
    });
  }
}

// One output row of the blend: the softmax of the logits over the candidates present (the
// base, every frame's samples in the (2 r_k + 1)^2 pixels around each output pixel, and the
// history), their y so weighted, clamped to [0, kBlendYMax] and back to linear colour (as
// model.from_y).
static void blend_row(const BlendArgs& a) {
  const size_t W = size_t(a.W), Wz = W + 2 * size_t(a.r);
  const size_t plane = Wz * (size_t(a.H) + 2 * size_t(a.r));
  for_lanes(a.W, [&](auto t, int X) {
    using T = decltype(t);
    // The largest logit present (the base and the history always are).
    T m = ld<T>(a.logits + X);
    size_t c = 1;
    using I = lanes_int<T>;
    I direct[kBlendMaxFrames];  // the frames read where they are: their samples' indices
    // The current frame's samples by column (a row of them where row_at holds one): the same
    // columns on every row of the window.
    static_assert(kBlendRadius == 1);  // (cols below: X - r0, X, X + r0 for r0 <= 1)
    const int r0 = a.rk[0];
    Picks<I> cols[2 * kBlendRadius + 1] = {Picks(ldi<I>(a.col_at + X - r0)),
                                           Picks(ldi<I>(a.col_at + X)),
                                           Picks(ldi<I>(a.col_at + X + r0))};
    auto row_at = [&](int dy) { return a.Y + dy < 0 || a.Y + dy >= a.H ? -1 : a.row_at[a.Y + dy]; };
    for (int dy = -r0; dy <= r0; ++dy) {
      if (row_at(dy) < 0) {
        c += size_t(2 * r0 + 1);
        continue;
      }
      for (int dx = -r0; dx <= r0; ++dx, ++c) {
        const T l = ld<T>(a.logits + c * W + size_t(X));
        m = cols[dx + r0].i >= 0 ? vmax(m, l) : m;
      }
    }
    for (int k = 1; k < a.frames; ++k) {
      const int rk = a.rk[k];
      if (!a.z[k] && a.at[k]) {
        direct[k] = ldi<I>(a.at[k] + size_t(a.Y) * W + size_t(X));
        const T l = ld<T>(a.logits + c * W + size_t(X));
        m = direct[k] >= 0 ? vmax(m, l) : m;
        ++c;
        continue;
      }
      if (!a.z[k]) {
        c += size_t((2 * rk + 1) * (2 * rk + 1));
        continue;
      }
      for (int dy = -rk; dy <= rk; ++dy) {
        const float* p = a.z[k] + 3 * plane + size_t(a.Y + a.r + dy) * Wz + size_t(a.r + X);
        for (int dx = -rk; dx <= rk; ++dx, ++c) {
          const T l = ld<T>(a.logits + c * W + size_t(X));
          m = ld<T>(p + dx) > 0.0f ? vmax(m, l) : m;
        }
      }
    }
    const T lh = ld<T>(a.logits + c * W + size_t(X));  // the history's, the last
    m = vmax(m, lh);
    // The base, bilinear: the columns' indices span a few samples (one load and a permute).
    const I i0 = ldi<I>(a.i0 + X), i1 = ldi<I>(a.i1 + X);
    const int lo = a.i0[X], hi = a.i1[X + lanes_of<T> - 1];
    const T tx = ld<T>(a.tx + X);
    T base[3];
    for (size_t ch = 0; ch < 3; ++ch) {
      const float* p0 = a.y + ch * a.n + a.j0;
      const float* p1 = a.y + ch * a.n + a.j1;
      const T top = lookup(p0, i0, lo, hi) + tx * (lookup(p0, i1, lo, hi) - lookup(p0, i0, lo, hi));
      const T bot = lookup(p1, i0, lo, hi) + tx * (lookup(p1, i1, lo, hi) - lookup(p1, i0, lo, hi));
      base[ch] = top + a.ty * (bot - top);
    }
    const T e0 = vexp2((ld<T>(a.logits + X) - m) * kLog2e);
    const T eh = vexp2((lh - m) * kLog2e);
    const float* h = a.hist + X;
    T s = e0 + eh, y0 = e0 * base[0] + eh * ld<T>(h),
      y1 = e0 * base[1] + eh * ld<T>(h + a.hist_plane),
      y2 = e0 * base[2] + eh * ld<T>(h + 2 * a.hist_plane);
    c = 1;
    for (int dy = -r0; dy <= r0; ++dy) {
      // Rows without samples add nothing (+0 to sums of non-negative terms).
      const int j = row_at(dy);
      if (j < 0) {
        c += size_t(2 * r0 + 1);
        continue;
      }
      for (int dx = -r0; dx <= r0; ++dx, ++c) {
        const T l = ld<T>(a.logits + c * W + size_t(X));
        T e = vexp2((l - m) * kLog2e);
        e = cols[dx + r0].i >= 0 ? e : T{};
        T v[3];
        samples_at(a.y + size_t(j) * size_t(a.w), a.n, cols[dx + r0], v);
        s += e;
        y0 += e * v[0], y1 += e * v[1], y2 += e * v[2];
      }
    }
    for (int k = 1; k < a.frames; ++k) {
      const int rk = a.rk[k];
      if (!a.z[k] && a.at[k]) {
        const T l = ld<T>(a.logits + c * W + size_t(X));
        T e = vexp2((l - m) * kLog2e);
        e = direct[k] >= 0 ? e : T{};
        T v[3];
        samples_at(a.ylow[k], a.n, Picks(direct[k]), v);
        s += e;
        y0 += e * v[0], y1 += e * v[1], y2 += e * v[2];
        ++c;
        continue;
      }
      if (!a.z[k]) {
        c += size_t((2 * rk + 1) * (2 * rk + 1));
        continue;
      }
      for (int dy = -rk; dy <= rk; ++dy) {
        const float* p = a.z[k] + size_t(a.Y + a.r + dy) * Wz + size_t(a.r + X);
        for (int dx = -rk; dx <= rk; ++dx, ++c) {
          const T l = ld<T>(a.logits + c * W + size_t(X));
          T e = vexp2((l - m) * kLog2e);
          e = ld<T>(p + 3 * plane + dx) > 0.0f ? e : T{};
          s += e;
          y0 += e * ld<T>(p + dx), y1 += e * ld<T>(p + plane + dx),
              y2 += e * ld<T>(p + 2 * plane + dx);
        }
      }
    }
    const T inv = 1.0f / s;
    y0 = vmin(vmax(y0 * inv, T{}), T{} + kBlendYMax);
    y1 = vmin(vmax(y1 * inv, T{}), T{} + kBlendYMax);
    y2 = vmin(vmax(y2 * inv, T{}), T{} + kBlendYMax);
    const T den = 1.0f / vmax(1.0f - (kLuma[0] * y0 + kLuma[1] * y1 + kLuma[2] * y2), T{} + 1e-3f);
    st_rgb(a.out + 3 * size_t(X), y0 * den, y1 * den, y2 * den);
  });
}
