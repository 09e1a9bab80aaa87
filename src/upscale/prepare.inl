// The upsampler's low-resolution stages (model.py: the inputs, their 3x3 statistics, the
// history test and the network's features) for one instruction set; included by
// reconstruct_*.cpp inside a namespace of their own, after core/simd/lanes.inl. Bodies are written
// once for float and the ISA's vector (for_lanes); neighbours outside the image are clamped
// to its edge, so the vector form runs where all its lanes' neighbours are inside and the
// float form takes the border columns.

template <class T>
static inline T luma3(T r, T g, T b) {
  return kLuma[0] * r + kLuma[1] * g + kLuma[2] * b;
}
// v where finite, else 0, lane by lane (the scalar form: sampling.inl).
static inline vfloat finite_or_zero(vfloat v) {
  return ((vint)v & 0x7F800000) != 0x7F800000 ? v : vfloat{};
}
template <class T>
static inline T clampv(T v, float lo, float hi) {
  return vmin(vmax(v, T{} + lo), T{} + hi);
}
// Lane l: pixel i + l of a channels-last image with c channels.
template <class T>
static inline T ld_channel(const float* img, int c, int i) {
  if constexpr (lanes_of<T> == 1)
    return img[size_t(c) * size_t(i)];
  else
    return vgather(img + size_t(c) * size_t(i), lane_iota(vint{}) * c);
}

static void input_rows(const InputArgs& a, int r0, int r1) {
  const LowRes& lr = a.lr;
  const size_t n = lr.n;
  const int begin = r0 * lr.w, end = r1 * lr.w;
  for_lanes_in(begin, end, [&](auto tag, int p) {
    using T = decltype(tag);
    T c[3];
    for (int k = 0; k < 3; ++k) c[k] = vmax(finite_or_zero(ld_channel<T>(a.color + k, 3, p)), T{});
    const T s = 1.0f / (1.0f + luma3(c[0], c[1], c[2]));
    for (int k = 0; k < 3; ++k) st(lr.y + size_t(k) * n + size_t(p), c[k] * s);
    st(lr.depth + p,
       a.depth ? vmax(finite_or_zero(ld<T>(a.depth + p)), T{}) : T{} + 1.0f);  // one channel
    for (int k = 0; k < 2; ++k)  // beyond any frame, and safe to convert to int
      st(lr.motion + size_t(k) * n + size_t(p),
         a.mc
             ? clampv(finite_or_zero(ld_channel<T>(a.motion + k, a.mc, p)), -kMaxMotion, kMaxMotion)
             : T{});
  });
}

// mu, sigma (3x3 mean and standard deviation of y per channel) and mdil (the motion of the
// least depth in the 3x3 window, sky = 0 counting as farthest, the first of equals in
// row-major order).
static void stats_rows(const LowRes& lr, int r0, int r1) {
  const int w = lr.w, h = lr.h;
  const size_t n = lr.n;
  for (int j = r0; j < r1; ++j) {
    const size_t rows[3] = {size_t(clampi(j - 1, 0, h - 1)) * size_t(w), size_t(j) * size_t(w),
                            size_t(clampi(j + 1, 0, h - 1)) * size_t(w)};
    auto pixel = [&](auto tag, int i) {
      using T = decltype(tag);
      constexpr bool vec = lanes_of < T >> 1;
      // Columns i - 1, i, i + 1: the vector form runs only where they are inside.
      const int cols[3] = {vec ? i - 1 : clampi(i - 1, 0, w - 1), i,
                           vec ? i + 1 : clampi(i + 1, 0, w - 1)};
      const size_t p = rows[1] + size_t(i);
      for (int k = 0; k < 3; ++k) {
        const float* y = lr.y + size_t(k) * n;
        T s1{}, s2{};
        for (int b = 0; b < 3; ++b) {
          T c1{}, c2{};
          for (int a = 0; a < 3; ++a) {
            const T v = ld<T>(y + rows[a] + size_t(cols[b]));
            c1 = c1 + v, c2 = c2 + v * v;
          }
          s1 = s1 + c1, s2 = s2 + c2;
        }
        const T m = s1 / 9.0f;
        st(lr.mu + size_t(k) * n + p, m);
        st(lr.sigma + size_t(k) * n + p, vsqrt(vmax(s2 / 9.0f - m * m, T{})));
      }
      T best = T{} + 3e38f, mx = ld<T>(lr.motion + p), my = ld<T>(lr.motion + n + p);
      for (int b = 0; b < 3; ++b)
        for (int a = 0; a < 3; ++a) {
          const size_t q = rows[b] + size_t(cols[a]);
          const T d0 = ld<T>(lr.depth + q);
          const T d = d0 > 0.0f ? d0 : T{} + 3e38f;
          const auto nearer = d < best;
          best = nearer ? d : best;
          mx = nearer ? ld<T>(lr.motion + q) : mx;
          my = nearer ? ld<T>(lr.motion + n + q) : my;
        }
      st(lr.mdil + p, mx), st(lr.mdil + n + p, my);
    };
    pixel(0.0f, 0);
    if (w > 2) for_lanes_in(1, w - 1, pixel);
    if (w > 1) pixel(0.0f, w - 1);
  }
}

// keep = 1 where the history of a pixel shows the surface it shows: one of the four previous
// samples around where its sample was (its position plus mdil, in the previous frame's
// sample grid, jitter included; edges clamped) has a depth within kDisocclusion of its own
// plus its depth's slope (the change to the next sample on the smoother side, in x plus in
// y: at most a pixel separates the two frames' samples), or both are sky. (model.keep_history)
static void disocclusion_rows(const HistoryArgs& a, int r0, int r1) {
  const LowRes& lr = a.lr;
  const int w = lr.w, h = lr.h;
  for (int j = r0; j < r1; ++j) {
    const float* up = lr.depth + size_t(clampi(j - 1, 0, h - 1)) * size_t(w);
    const float* mid = lr.depth + size_t(j) * size_t(w);
    const float* down = lr.depth + size_t(clampi(j + 1, 0, h - 1)) * size_t(w);
    auto pixel = [&](auto tag, int i) {
      using T = decltype(tag);
      using I = lanes_int<T>;
      constexpr bool vec = lanes_of < T >> 1;
      const size_t p = size_t(j) * size_t(w) + size_t(i);
      const T d = ld<T>(mid + i);
      const T left = vabs(ld<T>(mid + (vec ? i - 1 : clampi(i - 1, 0, w - 1))) - d),
              right = vabs(ld<T>(mid + (vec ? i + 1 : clampi(i + 1, 0, w - 1))) - d);
      const T above = vabs(ld<T>(up + i) - d), below = vabs(ld<T>(down + i) - d);
      const T slope = vmin(left, right) + vmin(above, below);
      const T tol = kDisocclusion * vmax(d, T{} + kMinDepth) + slope;
      const I qx = vfloor(((vindex(T{}, i) + a.jx) + ld<T>(lr.mdil + p)) - a.prev_jx);
      const I qy = vfloor(((float(j) + a.jy) + ld<T>(lr.mdil + lr.n + p)) - a.prev_jy);
      const auto sky = vnot(d > 0.0f);
      auto same = sky & vnot(sky);  // false, in the mask type of T
      for (int b = 0; b <= 1; ++b) {
        const I row = vmini(vmaxi(qy + b, I{}), I{} + (h - 1)) * w;
        for (int c = 0; c <= 1; ++c) {
          const T dq = vgather(a.prev_depth, row + vmini(vmaxi(qx + c, I{}), I{} + (w - 1)));
          // Both surfaces within tol, or both sky (depths are >= 0).
          const auto near = vabs(dq - d) <= tol, sky_q = vnot(dq > 0.0f);
          same = same | ((sky == sky_q) & (sky | near));
        }
      }
      st(lr.keep + p, same ? T{} + 1.0f : T{});
    };
    pixel(0.0f, 0);
    if (w > 2) for_lanes_in(1, w - 1, pixel);
    if (w > 1) pixel(0.0f, w - 1);
  }
}

// The history (three planes of W x H) at (x, y) bilinearly, edges clamped, as luminance.
template <class T>
static inline T history_luma(const float* hist, int W, int H, T x, T y) {
  using I = lanes_int<T>;
  const T xf = x - 0.5f, yf = y - 0.5f;
  const I x0 = vfloor(xf), y0 = vfloor(yf);
  const T tx = xf - vfloat_of(x0), ty = yf - vfloat_of(y0);
  const I ix0 = vmini(vmaxi(x0, I{}), I{} + (W - 1)),
          ix1 = vmini(vmaxi(x0 + 1, I{}), I{} + (W - 1));
  const I iy0 = vmini(vmaxi(y0, I{}), I{} + (H - 1)) * W,
          iy1 = vmini(vmaxi(y0 + 1, I{}), I{} + (H - 1)) * W;
  T c[3];
  for (int k = 0; k < 3; ++k) {
    const float* p = hist + size_t(k) * size_t(W) * size_t(H);
    const T p00 = vgather(p, iy0 + ix0), p01 = vgather(p, iy0 + ix1), p10 = vgather(p, iy1 + ix0),
            p11 = vgather(p, iy1 + ix1);
    c[k] = (1.0f - ty) * ((1.0f - tx) * p00 + tx * p01) + ty * ((1.0f - tx) * p10 + tx * p11);
  }
  return luma3(c[0], c[1], c[2]);
}

// The network's 8 low-resolution features (model.features): luminance, the history's
// luminance against it and against the 3x3 mean, the 3x3 deviation, the relative depth
// change since the previous frame, the motion's length, validity and the depth edge.
static void features_rows(const HistoryArgs& a, int r0, int r1) {
  const LowRes& lr = a.lr;
  const int w = lr.w, h = lr.h;
  const size_t n = lr.n;
  const float f = float(a.f);
  for (int j = r0; j < r1; ++j) {
    const float* up = lr.depth + size_t(clampi(j - 1, 0, h - 1)) * size_t(w);
    const float* mid = lr.depth + size_t(j) * size_t(w);
    const float* down = lr.depth + size_t(clampi(j + 1, 0, h - 1)) * size_t(w);
    auto pixel = [&](auto tag, int i) {
      using T = decltype(tag);
      using I = lanes_int<T>;
      constexpr bool vec = lanes_of < T >> 1;
      const size_t p = size_t(j) * size_t(w) + size_t(i);
      auto plane3 = [&](const float* img) {
        return luma3(ld<T>(img + p), ld<T>(img + n + p), ld<T>(img + 2 * n + p));
      };
      const T L = plane3(lr.y), muL = plane3(lr.mu), sigL = plane3(lr.sigma);
      const T mx = ld<T>(lr.mdil + p), my = ld<T>(lr.mdil + n + p);
      const T d = ld<T>(mid + i);
      T valid{}, Lh = L, dchange{};
      if (a.history) {
        const T hx = f * ((vindex(T{}, i) + a.jx) + mx), hy = f * ((float(j) + a.jy) + my);
        const auto inside = (hx >= 0.0f) & (hx < float(a.W)) & (hy >= 0.0f) & (hy < float(a.H));
        valid = inside ? T{} + 1.0f : T{};
        Lh = history_luma(a.hist, a.W, a.H, hx, hy);
        const I px = vmini(vmaxi(vfloor((vindex(T{}, i) + 0.5f) + mx), I{}), I{} + (w - 1));
        const I py = vmini(vmaxi(vfloor((float(j) + 0.5f) + my), I{}), I{} + (h - 1));
        const T dp = vgather(a.prev_depth, py * w + px);
        const auto both = (d > 0.0f) & (dp > 0.0f);
        const auto one = (d > 0.0f) != (dp > 0.0f);
        const T rel = clampv((dp - d) / vmax(d, T{} + kMinDepth), -1.0f, 1.0f);
        dchange = both ? rel : (one ? T{} + 1.0f : T{});
      }
      const T mmag = vmin(vsqrt(mx * mx + my * my) / 8.0f, T{} + 1.0f);
      const T dn[4] = {ld<T>(up + i), ld<T>(mid + (vec ? i - 1 : clampi(i - 1, 0, w - 1))),
                       ld<T>(mid + (vec ? i + 1 : clampi(i + 1, 0, w - 1))), ld<T>(down + i)};
      T edge{};
      for (const T& v : dn) edge = vmax(edge, vabs(v - d));
      edge = vmin(edge / vmax(d, T{} + kMinDepth), T{} + 1.0f);
      const T out[8] = {
          L, (Lh - L) * valid, sigL, (Lh - muL) * valid, dchange * valid, mmag, valid, edge};
      for (int k = 0; k < 8; ++k) st(lr.feat + size_t(k) * n + p, out[k]);
    };
    pixel(0.0f, 0);
    if (w > 2) for_lanes_in(1, w - 1, pixel);
    if (w > 1) pixel(0.0f, w - 1);
  }
}
