// The reconstruction loop (model.step) for one instruction set; included by reconstruct_*.cpp
// inside a namespace of their own, after core/simd/lanes.inl. Each output row is done kLanes
// pixels at a time (T = vfloat) and, in images narrower than that, pixel by pixel (T = float):
// the body is written once for both.
//
// Per output row the three current-frame rows are blended vertically (vert) and the parameter
// grid's two rows (gv); those and the low-resolution planes' row j0 (mu, sigma, motion, keep)
// are read at the lanes' column indices, which are non-decreasing and span a few entries, by
// one load and a permute (lookup). The history is three planes, so its taps are mostly plain
// loads (sample_history).

// The current frame's three rows blended for an output row (vert) and the grid's two (gv),
// planar and padded by kLanes (lookup's loads).
struct RowPlanes {
  size_t lw = 0, lgw = 0;
  std::vector<float> vert, gv;
  RowPlanes(int w, int gw)
      : lw(size_t(w) + kLanes), lgw(size_t(gw) + kLanes), vert(3 * lw, 0.0f), gv(3 * lgw, 0.0f) {}
};

struct RowContext {
  const Recon* a;
  const RowPlanes* rp;
  size_t plane;  // W * H: one history plane
  int Y, j0;
  float dy0, wy_sum;
};

// Catmull-Rom weights of the four taps around t in [0, 1), lane by lane.
template <class T>
static inline void catmull_rom_weights(T t, T w[4]) {
  const T t2 = t * t, t3 = t2 * t;
  w[0] = -0.5f * t3 + t2 - 0.5f * t;
  w[1] = 1.5f * t3 - 2.5f * t2 + 1.0f;
  w[2] = -1.5f * t3 + 2.0f * t2 + 0.5f * t;
  w[3] = 0.5f * t3 - 0.5f * t2;
}

template <class T>
static inline T splat(float v) {
  return T{} + v;
}

// One channel of the history from its rows ymin - 1 .. ymin + rows - 2 (rows: 4, or 5 where
// some lanes' taps start a row lower: `down`), each filtered horizontally once with the lanes'
// taps (taps(p, t): row p's four taps from column `col` on), the lanes one row lower taking the
// next row's: the Catmull-Rom sum clamped to the range of the four central taps.
template <class T, class Mask, class Taps>
static inline T filter_rows(const float* channel, int W, int ymin, int col, int rows, Mask down,
                            const T wx[4], const T wy[4], Taps&& taps) {
  T h[5], lo[5], hi[5];
  for (int k = 0; k < rows; ++k) {
    T t[4];
    taps(channel + size_t(ymin + k - 1) * size_t(W) + size_t(col), t);
    h[k] = wx[0] * t[0];
    for (int i = 1; i < 4; ++i) h[k] = h[k] + wx[i] * t[i];
    lo[k] = vmin(t[1], t[2]), hi[k] = vmax(t[1], t[2]);
  }
  if (rows == 5)
    for (int k = 0; k < 4; ++k)
      h[k] = down ? h[k + 1] : h[k], lo[k] = down ? lo[k + 1] : lo[k],
      hi[k] = down ? hi[k + 1] : hi[k];
  T acc = wy[0] * h[0];
  for (int j = 1; j < 4; ++j) acc = acc + wy[j] * h[j];
  return vmin(vmax(acc, vmin(lo[1], lo[2])), vmax(hi[1], hi[2]));
}

// The history (three planes of W x H) at (x, y), pixel centres at k + 0.5, edges clamped:
// Catmull-Rom clamped per channel to the range of the four central taps (its bilinear
// footprint), so the negative lobes cannot overshoot what the history holds there.
//
// Lane l's 4 x 4 taps start at column x1_l - 1 = b_l + l - 1 and row y1_l - 1. A camera move
// shifts neighbouring pixels alike, so away from the border b and y1 mostly take one or two
// neighbouring values across the lanes: then each tap row is read with plain loads at bmin
// and bmin + 1 (the lanes with b = bmin + 1 take the second) and filtered once, and the lanes
// with y1 = ymin + 1 take the next row's result. Where the columns spread further (motion
// that changes across a depth edge) but fit in a window of 2 kLanes, permutes of the window;
// elsewhere the taps are gathered at clamped indices.
template <class T>
static inline void sample_history(const float* hist, size_t plane, int W, int H, T x, T y,
                                  T out[3]) {
  using I = lanes_int<T>;
  constexpr int L = lanes_of<T>;
  const T xf = x - 0.5f, yf = y - 0.5f;
  const I x1 = vfloor(xf), y1 = vfloor(yf);
  T wx[4], wy[4];
  catmull_rom_weights(xf - vfloat_of(x1), wx);
  catmull_rom_weights(yf - vfloat_of(y1), wy);
  const I b = x1 - lane_iota(x1);
  const int bmin = lane_min(b), bmax = lane_max(b), ymin = lane_min(y1), ymax = lane_max(y1);
  const auto down = y1 != ymin;
  const int rows = ymax > ymin ? 5 : 4;
  if (bmax - bmin <= 1 && ymax - ymin <= 1 && bmin >= 1 && bmin + L + 3 <= W && ymin >= 1 &&
      ymax + 2 < H) {
    const auto right = b != bmin;
    const bool shift = bmax > bmin;
    for (int c = 0; c < 3; ++c)
      out[c] = filter_rows(hist + size_t(c) * plane, W, ymin, bmin - 1, rows, down, wx, wy,
                           [&](const float* p, T t[4]) {
                             T s[5];
                             for (int m = 0; m < (shift ? 5 : 4); ++m) s[m] = ld<T>(p + m);
                             for (int i = 0; i < 4; ++i)
                               t[i] = shift ? (right ? s[i + 1] : s[i]) : s[i];
                           });
    return;
  }
  if constexpr (L > 1) {
    const int xmin = lane_min(x1), xmax = lane_max(x1);
    if (xmax - xmin + 3 < 2 * L && ymax - ymin <= 1 && xmin >= 1 && xmin + 2 * L - 1 <= W &&
        ymin >= 1 && ymax + 2 < H) {
      // A window of 2 kLanes pixels from column xmin - 1, each lane's taps permuted out of it.
      const vint dx = x1 - xmin;
      for (int c = 0; c < 3; ++c)
        out[c] = filter_rows(hist + size_t(c) * plane, W, ymin, xmin - 1, rows, down, wx, wy,
                             [&](const float* p, vfloat t[4]) {
                               const vfloat lo = ld<vfloat>(p), hi = ld<vfloat>(p + kLanes);
                               for (int i = 0; i < 4; ++i) t[i] = perm2(lo, hi, dx + i);
                             });
      return;
    }
  }
  I ix[4], iy[4];
  for (int i = 0; i < 4; ++i) {
    ix[i] = vmini(vmaxi(x1 + (i - 1), I{}), I{} + (W - 1));
    iy[i] = vmini(vmaxi(y1 + (i - 1), I{}), I{} + (H - 1)) * W;
  }
  for (int c = 0; c < 3; ++c) {
    const float* p = hist + size_t(c) * plane;
    T acc{}, lo = splat<T>(3e38f), hi = splat<T>(-3e38f);
    for (int j = 0; j < 4; ++j) {
      T t[4];
      for (int i = 0; i < 4; ++i) t[i] = vgather(p, iy[j] + ix[i]);
      T r = wx[0] * t[0];
      for (int i = 1; i < 4; ++i) r = r + wx[i] * t[i];
      acc = acc + wy[j] * r;
      if (j == 1 || j == 2) lo = vmin(lo, vmin(t[1], t[2])), hi = vmax(hi, vmax(t[1], t[2]));
    }
    out[c] = vmin(vmax(acc, lo), hi);
  }
}

// Output pixels X .. X + lanes_of<T> - 1 of the context's row.
template <class T>
static inline void reconstruct_pixels(const RowContext& r, int X) {
  using I = lanes_int<T>;
  constexpr int L = lanes_of<T>;
  const Recon& a = *r.a;
  const RowPlanes& rp = *r.rp;
  const size_t x = size_t(X);
  // The current frame: 3 taps of the vertically blended rows.
  const I i0 = ldi<I>(&a.ax->i0[x]);
  const int ilo = a.ax->i0[x], ihi = a.ax->i0[x + L - 1];
  const I cm = vmaxi(i0 - 1, I{}), cp = vmini(i0 + 1, I{} + (a.lr.w - 1));
  const int clo = std::max(ilo - 1, 0), chi = std::min(ihi + 1, a.lr.w - 1);
  const T wx0 = ld<T>(&a.ax->w[0][x]), wx1 = ld<T>(&a.ax->w[1][x]), wx2 = ld<T>(&a.ax->w[2][x]);
  const T norm = 1.0f / ((wx0 + wx1 + wx2) * r.wy_sum);
  T o[3];
  for (int c = 0; c < 3; ++c) {
    const float* v = &rp.vert[size_t(c) * rp.lw];
    o[c] = (wx0 * lookup(v, cm, clo, chi) + wx1 * lookup(v, i0, clo, chi) +
            wx2 * lookup(v, cp, clo, chi)) *
           norm;
  }
  if (a.history) {
    // Row j0 of a low-resolution plane at the lanes' nearest samples.
    const size_t row = size_t(r.j0) * size_t(a.lr.w);
    auto low = [&](const float* plane) { return lookup(plane + row, i0, ilo, ihi); };
    const T hx = (vindex(T{}, X) + 0.5f) + float(a.f) * low(a.lr.mdil),
            hy = splat<T>(float(r.Y) + 0.5f) + float(a.f) * low(a.lr.mdil + a.lr.n);
    const auto valid = (hx >= 0.0f) & (hx < float(a.W)) & (hy >= 0.0f) & (hy < float(a.H)) &
                       (low(a.lr.keep) != 0.0f);
    // Where no lane's history is valid, alpha = 1: the current frame alone.
    if (any_of(valid)) {
      // Parameters: bilinear from the grid (its rows already blended into gv).
      const I ga = ldi<I>(&a.gx->a[x]), gb = ldi<I>(&a.gx->b[x]);
      const int glo = a.gx->a[x], ghi = a.gx->b[x + L - 1];
      const T tx = ld<T>(&a.gx->t[x]);
      T prm[3];
      for (int k = 0; k < 3; ++k) {
        const float* g = &rp.gv[size_t(k) * rp.lgw];
        prm[k] = (1.0f - tx) * lookup(g, ga, glo, ghi) + tx * lookup(g, gb, glo, ghi);
      }
      const T dx0 = ld<T>(&a.ax->d0[x]);
      const T conf = vexp_neg(T{} - prm[2] * float(a.f * a.f) * (dx0 * dx0 + r.dy0 * r.dy0));
      const T alpha = valid ? prm[0] * conf : splat<T>(1.0f);
      T hc[3];
      sample_history(a.hist, r.plane, a.W, a.H, hx, hy, hc);
      for (int c = 0; c < 3; ++c) {
        const T m = low(a.lr.mu + size_t(c) * a.lr.n),
                sg = prm[1] * low(a.lr.sigma + size_t(c) * a.lr.n);
        const T v = vmin(vmax(hc[c], m - sg), m + sg);
        o[c] = v + alpha * (o[c] - v);
      }
    }
  }
  const size_t P = size_t(r.Y) * size_t(a.W) + x;
  T yc[3];
  for (int c = 0; c < 3; ++c) {
    st(a.next + size_t(c) * r.plane + P, o[c]);
    yc[c] = vmax(o[c], T{});
  }
  const T s =
      1.0f / vmax(1.0f - (kLuma[0] * yc[0] + kLuma[1] * yc[1] + kLuma[2] * yc[2]), splat<T>(1e-3f));
  st_rgb(a.out + 3 * P, yc[0] * s, yc[1] * s, yc[2] * s);
}

static void reconstruct_rows(const Recon& a, int r0, int r1) {
  const LowRes& lr = a.lr;
  RowPlanes rp(lr.w, a.gw);
  RowContext r{&a, &rp, size_t(a.W) * size_t(a.H), 0, 0, 0.0f, 0.0f};
  for (int Y = r0; Y < r1; ++Y) {
    const size_t yy = size_t(Y);
    const int j0 = a.ay->i0[yy];
    const float wy[3] = {a.ay->w[0][yy], a.ay->w[1][yy], a.ay->w[2][yy]};
    const size_t rows[3] = {size_t(clampi(j0 - 1, 0, lr.h - 1)) * size_t(lr.w),
                            size_t(j0) * size_t(lr.w),
                            size_t(clampi(j0 + 1, 0, lr.h - 1)) * size_t(lr.w)};
    // The current frame's three rows, weighted for this output row: vert_c[i] = sum_b wy_b
    // y_c(i, row_b); the grid's two rows likewise.
    for (size_t c = 0; c < 3; ++c) {
      const float* y = lr.y + c * lr.n;
      float* v = &rp.vert[c * rp.lw];
      for (size_t i = 0; i < size_t(lr.w); ++i)
        v[i] = wy[0] * y[rows[0] + i] + wy[1] * y[rows[1] + i] + wy[2] * y[rows[2] + i];
    }
    const float ty = a.gy->t[yy];
    const float* ga = &a.grid[size_t(a.gy->a[yy]) * size_t(a.gw) * 3];
    const float* gb = &a.grid[size_t(a.gy->b[yy]) * size_t(a.gw) * 3];
    for (size_t i = 0; i < size_t(a.gw); ++i)
      for (size_t c = 0; c < 3; ++c)
        rp.gv[c * rp.lgw + i] = (1 - ty) * ga[3 * i + c] + ty * gb[3 * i + c];
    r.Y = Y, r.j0 = j0, r.dy0 = a.ay->d0[yy], r.wy_sum = wy[0] + wy[1] + wy[2];
    if (a.W >= kLanes) {
      int X = 0;
      for (; X + kLanes <= a.W; X += kLanes) reconstruct_pixels<vfloat>(r, X);
      // The row's tail: the last kLanes pixels again (the same values where they overlap).
      if (X < a.W) reconstruct_pixels<vfloat>(r, a.W - kLanes);
    } else {
      for (int X = 0; X < a.W; ++X) reconstruct_pixels<float>(r, X);
    }
  }
}
