// Included by kernels_<isa>.cpp inside namespace kestrel::denoise::KESTREL_ISA_NS.
// Plain loops written for the auto-vectoriser (contiguous inner loops, no branches).

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

// Channels-last convolution for cout a multiple of 16, on an input zero-padded by one pixel
// on every side and to a multiple of 8 columns: blocks of 8 output pixels x 16 output
// channels held in registers (GCC vector extensions: one AVX-512 register, or two AVX /
// four SSE registers, per block row), each weight vector feeding 8 FMAs.
typedef float V16 __attribute__((vector_size(64)));

static void conv_rows_padded(const ConvArgs& a, const float* padded, int row0, int row1) {
  const int w = a.width, cin = a.cin, cout = a.cout, k = a.ksize, r = k / 2;
  const int wp = (w + 7) / 8 * 8, pw = wp + 2;
  for (int y = row0; y < row1; ++y)
    for (int x0 = 0; x0 < wp; x0 += 8)
      for (int cb = 0; cb < cout; cb += 16) {
        V16 bias;
        __builtin_memcpy(&bias, a.bias + cb, sizeof bias);
        V16 acc[8];
#pragma GCC unroll 8
        for (int b = 0; b < 8; ++b) acc[b] = bias;
        for (int ky = 0; ky < k; ++ky)
          for (int kx = 0; kx < k; ++kx) {
            const float* in = padded + (size_t(y + ky + 1 - r) * size_t(pw) + size_t(x0 + kx + 1 - r)) * size_t(cin);
            const float* wk = a.weights + size_t(ky * k + kx) * size_t(cin) * size_t(cout) + size_t(cb);
            for (int ci = 0; ci < cin; ++ci) {
              V16 wv;
              __builtin_memcpy(&wv, wk + size_t(ci) * size_t(cout), sizeof wv);
#pragma GCC unroll 8
              for (int b = 0; b < 8; ++b) acc[b] += in[size_t(b) * size_t(cin) + size_t(ci)] * wv;
            }
          }
        const V16 zero = {};
#pragma GCC unroll 8
        for (int b = 0; b < 8; ++b) {
          if (x0 + b >= w) break;
          V16 v = a.relu ? (acc[b] > zero ? acc[b] : zero) : acc[b];
          __builtin_memcpy(a.out + (size_t(y) * size_t(w) + size_t(x0 + b)) * size_t(cout) + size_t(cb), &v, sizeof v);
        }
      }
}

// Zero-pads a channels-last image by one pixel and to a multiple of 8 columns (rows in
// parallel; only the border is cleared).
static void pad_for_conv(const float* in, int w, int h, int c, std::vector<float>& out) {
  const int wp = (w + 7) / 8 * 8, pw = wp + 2;
  const size_t row_floats = size_t(pw) * size_t(c);
  out.resize(row_floats * size_t(h + 2));
  std::fill(out.begin(), out.begin() + std::ptrdiff_t(row_floats), 0.0f);
  std::fill(out.end() - std::ptrdiff_t(row_floats), out.end(), 0.0f);
  tbb::parallel_for(tbb::blocked_range<int>(0, h, 8), [&](const tbb::blocked_range<int>& r) {
    for (int y = r.begin(); y < r.end(); ++y) {
      float* dst = &out[size_t(y + 1) * row_floats];
      std::fill(dst, dst + c, 0.0f);
      std::memcpy(dst + c, in + size_t(y) * size_t(w) * size_t(c), sizeof(float) * size_t(w) * size_t(c));
      std::fill(dst + size_t(w + 1) * size_t(c), dst + row_floats, 0.0f);
    }
  });
}

static void conv_rows_any(const ConvArgs& a, int row0, int row1) {
  const int w = a.width, h = a.height, cin = a.cin, cout = a.cout, k = a.ksize, r = k / 2;
  for (int y = row0; y < row1; ++y)
    for (int x = 0; x < w; ++x) {
      float* o = a.out + (size_t(y) * size_t(w) + size_t(x)) * size_t(cout);
      for (int co = 0; co < cout; ++co) o[co] = a.bias[co];
      for (int ky = 0; ky < k; ++ky) {
        const int sy = y + ky - r;
        if (sy < 0 || sy >= h) continue;
        for (int kx = 0; kx < k; ++kx) {
          const int sx = x + kx - r;
          if (sx < 0 || sx >= w) continue;
          const float* ip = a.in + (size_t(sy) * size_t(w) + size_t(sx)) * size_t(cin);
          const float* wk = a.weights + size_t(ky * k + kx) * size_t(cin) * size_t(cout);
          for (int ci = 0; ci < cin; ++ci)
            for (int co = 0; co < cout; ++co) o[co] += ip[ci] * wk[size_t(ci) * size_t(cout) + size_t(co)];
        }
      }
      if (a.relu)
        for (int co = 0; co < cout; ++co) o[co] = o[co] > 0.0f ? o[co] : 0.0f;
    }
}

static void conv_rows(const ConvArgs& a, int row0, int row1) { conv_rows_any(a, row0, row1); }

// The interior of one tap over a span of pixels: p-side arrays, q-side arrays, accumulators.
static void atrous_span(int m, float hq, const float* __restrict px0, const float* __restrict px1,
                        const float* __restrict px2, const float* __restrict pn0, const float* __restrict pn1,
                        const float* __restrict pn2, const float* __restrict pz, const float* __restrict psc,
                        const float* __restrict psn, const float* __restrict psz, const float* __restrict q0,
                        const float* __restrict q1, const float* __restrict q2, const float* __restrict m0,
                        const float* __restrict m1, const float* __restrict m2, const float* __restrict qz,
                        float* __restrict r0, float* __restrict r1, float* __restrict r2, float* __restrict rw) {
  for (int i = 0; i < m; ++i) {
    const float d0 = px0[i] - q0[i], d1 = px1[i] - q1[i], d2 = px2[i] - q2[i];
    const float dot = pn0[i] * m0[i] + pn1[i] * m1[i] + pn2[i] * m2[i];
    const float nn = pn0[i] * pn0[i] + pn1[i] * pn1[i] + pn2[i] * pn2[i];
    const float nd = nn - dot > 0.0f ? nn - dot : 0.0f;
    const float dz = pz[i] - qz[i];
    const float e = psc[i] * (d0 * d0 + d1 * d1 + d2 * d2) + psn[i] * nd + psz[i] * (dz < 0.0f ? -dz : dz);
    const float wq = hq * exp_neg(-e);
    r0[i] += wq * q0[i];
    r1[i] += wq * q1[i];
    r2[i] += wq * q2[i];
    rw[i] += wq;
  }
}

static void atrous_finish(int n, const float* __restrict beta, const float* __restrict x0, const float* __restrict x1,
                          const float* __restrict x2, const float* __restrict acc0, const float* __restrict acc1,
                          const float* __restrict acc2, const float* __restrict wsum, float* __restrict o0,
                          float* __restrict o1, float* __restrict o2) {
  for (int i = 0; i < n; ++i) {
    const float inv = 1.0f / wsum[i];
    o0[i] = x0[i] + beta[i] * (acc0[i] * inv - x0[i]);
    o1[i] = x1[i] + beta[i] * (acc1[i] * inv - x1[i]);
    o2[i] = x2[i] + beta[i] * (acc2[i] * inv - x2[i]);
  }
}

static void atrous_rows(const AtrousArgs& a, int row0, int row1) {
  const int w = a.width, h = a.height, d = a.dilation;
  // Per row and chunk of 256 pixels: accumulate tap by tap over the chunk (contiguous,
  // vectorisable); taps outside the image are clamped to the border.
  constexpr int kChunk = 256;
  float acc0[kChunk], acc1[kChunk], acc2[kChunk], wsum[kChunk];
  for (int y = row0; y < row1; ++y) {
    const size_t row = size_t(y) * size_t(w);
    for (int c0 = 0; c0 < w; c0 += kChunk) {
      const int c1 = c0 + kChunk < w ? c0 + kChunk : w, n = c1 - c0;
      const float* x0 = a.x[0] + row + c0;
      const float* x1 = a.x[1] + row + c0;
      const float* x2 = a.x[2] + row + c0;
      const float* n0 = a.n[0] + row + c0;
      const float* n1 = a.n[1] + row + c0;
      const float* n2 = a.n[2] + row + c0;
      const float* zp = a.z + row + c0;
      const float* sc = a.sc + row + c0;
      const float* sn = a.sn + row + c0;
      const float* sz = a.sz + row + c0;
      // The centre tap weighs exactly 1 (every difference is 0, and n.n - n.n = 0).
      for (int i = 0; i < n; ++i) acc0[i] = x0[i], acc1[i] = x1[i], acc2[i] = x2[i], wsum[i] = 1.0f;
      for (int ty = -1; ty <= 1; ++ty) {
        int qy = y + ty * d;
        qy = qy < 0 ? 0 : (qy >= h ? h - 1 : qy);
        const size_t qrow = size_t(qy) * size_t(w);
        for (int tx = -1; tx <= 1; ++tx) {
          if (tx == 0 && ty == 0) continue;
          const float hq = (ty == 0 ? 2.0f : 1.0f) * (tx == 0 ? 2.0f : 1.0f) * 0.25f;
          const int off = tx * d;
          // Chunk-relative [lo, hi): c0 + i + off inside [0, w).
          int lo = -off - c0, hi = w - off - c0;
          lo = lo < 0 ? 0 : (lo > n ? n : lo);
          hi = hi > n ? n : (hi < lo ? lo : hi);
          auto tap = [&](int i, size_t q) {
            const float d0 = x0[i] - a.x[0][q], d1 = x1[i] - a.x[1][q], d2 = x2[i] - a.x[2][q];
            const float dot = n0[i] * a.n[0][q] + n1[i] * a.n[1][q] + n2[i] * a.n[2][q];
            const float nn = n0[i] * n0[i] + n1[i] * n1[i] + n2[i] * n2[i];
            const float nd = nn - dot > 0.0f ? nn - dot : 0.0f;
            const float dz = zp[i] - a.z[q];
            const float e = sc[i] * (d0 * d0 + d1 * d1 + d2 * d2) + sn[i] * nd + sz[i] * (dz < 0.0f ? -dz : dz);
            const float wq = hq * exp_neg(-e);
            acc0[i] += wq * a.x[0][q];
            acc1[i] += wq * a.x[1][q];
            acc2[i] += wq * a.x[2][q];
            wsum[i] += wq;
          };
          for (int i = 0; i < lo; ++i) tap(i, qrow);
          const size_t base = qrow + size_t(c0 + off + lo);
          atrous_span(hi - lo, hq, x0 + lo, x1 + lo, x2 + lo, n0 + lo, n1 + lo, n2 + lo, zp + lo, sc + lo, sn + lo, sz + lo,
                      a.x[0] + base, a.x[1] + base, a.x[2] + base, a.n[0] + base, a.n[1] + base, a.n[2] + base, a.z + base,
                      acc0 + lo, acc1 + lo, acc2 + lo, wsum + lo);
          for (int i = hi; i < n; ++i) tap(i, qrow + size_t(w - 1));
        }
      }
      atrous_finish(n, a.beta + row + c0, x0, x1, x2, acc0, acc1, acc2, wsum, a.out[0] + row + c0, a.out[1] + row + c0,
                    a.out[2] + row + c0);
    }
  }
}

// ---- The whole network per frame (model.py's forward), with this file's ISA. ----

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
  const float series = s * (2.0f + s2 * (0.6666667f + s2 * (0.4f + s2 * (0.2857143f + s2 * 0.2222222f))));
  return float(e) * 0.69314718f + series;
}

// exp(x) for x in [-36, 88] (0 below, clamped above).
static inline float exp_any(float x) {
  x = x > 88.0f ? 88.0f : x;
  return exp_neg(x - 44.0f) * 1.2851600e19f;  // e^44, so both halves stay in range
}

template <class F>
static void parallel_rows(int h, int grain, F&& f) {
  tbb::parallel_for(tbb::blocked_range<int>(0, h, grain), [&](const tbb::blocked_range<int>& r) { f(r.begin(), r.end()); });
}

static void conv_layer(const ConvLayer& l, const std::vector<float>& in, int w, int h, std::vector<float>& out, bool relu,
                       std::vector<float>& scratch) {
  out.resize(size_t(w) * size_t(h) * size_t(l.cout));
  ConvArgs a;
  a.in = in.data(), a.weights = l.weights.data(), a.bias = l.bias.data(), a.out = out.data();
  a.width = w, a.height = h, a.cin = l.cin, a.cout = l.cout, a.ksize = l.ksize, a.relu = relu;
  if (l.cout % 16 == 0) {
    pad_for_conv(in.data(), w, h, l.cin, scratch);
    parallel_rows(h, 2, [&](int r0, int r1) { conv_rows_padded(a, scratch.data(), r0, r1); });
  } else {
    parallel_rows(h, 2, [&](int r0, int r1) { conv_rows_any(a, r0, r1); });
  }
}

static void ensure(Planes& p, int w, int h, int c) {
  if (p.width != w || p.height != h || p.channels != c) p = Planes(w, h, c);
}

struct UpTap {
  int i0, i1;
  float f;
};

// PyTorch's bilinear (align_corners=False) source indices and weight for output i.
static UpTap up_tap(int i, int in, float scale) {
  float s = scale * (float(i) + 0.5f) - 0.5f;
  s = s < 0 ? 0 : s;
  const int i0 = int(s);
  return {i0, i0 < in - 1 ? i0 + 1 : i0, s - float(i0)};
}

static const Planes& network(const NeuralWeights& nw, const Planes& in, Planes& state, bool recurrent, Workspace& ws,
                             StageTimes* times) {
  using clock = std::chrono::steady_clock;
  auto t = clock::now();
  auto lap = [&](double* slot) {
    const auto now = clock::now();
    if (times) *slot = std::chrono::duration<double, std::milli>(now - t).count();
    t = now;
  };
  StageTimes dummy;
  StageTimes& st = times ? *times : dummy;
  const int W = in.width, H = in.height;
  const size_t N = size_t(W) * size_t(H);
  const int Wq = W / 4, Hq = H / 4;
  ensure(ws.x, W, H, 3);
  ensure(ws.yw, W, H, 3);
  ws.zw.resize(N), ws.valid.resize(N), ws.zc.resize(N);
  const float* z = in.ch(9);
  const bool have_state = recurrent && state.width == W && state.height == H && state.channels == 4;
  // x = log1p(demodulated colour); the previous output and depth warped by the motion.
  parallel_rows(H, 8, [&](int r0, int r1) {
    for (int y = r0; y < r1; ++y) {
      const size_t row = size_t(y) * size_t(W);
      for (int c = 0; c < 3; ++c) {
        const float* col = in.ch(c) + row;
        const float* alb = in.ch(3 + c) + row;
        float* xo = ws.x.ch(c) + row;
        for (int i = 0; i < W; ++i) {
          const float a = alb[i] > 0.0f ? alb[i] : 0.0f;
          const float v = col[i] > 0.0f ? col[i] : 0.0f;
          xo[i] = log1p_pos(v / (a + kAlbedoEps));
        }
      }
      for (int i = 0; i < W; ++i) ws.zc[row + size_t(i)] = z[row + size_t(i)] > kMinDepth ? z[row + size_t(i)] : kMinDepth;
      if (!have_state) {
        for (int c = 0; c < 3; ++c) std::memcpy(ws.yw.ch(c) + row, ws.x.ch(c) + row, sizeof(float) * size_t(W));
        std::memcpy(ws.zw.data() + row, z + row, sizeof(float) * size_t(W));
        std::fill(ws.valid.begin() + std::ptrdiff_t(row), ws.valid.begin() + std::ptrdiff_t(row + size_t(W)), 0.0f);
        continue;
      }
      for (int i = 0; i < W; ++i) {
        const size_t p = row + size_t(i);
        const float px = float(i) + in.ch(11)[p], py = float(y) + in.ch(12)[p];
        ws.valid[p] = (px >= -0.5f && px <= float(W) - 0.5f && py >= -0.5f && py <= float(H) - 0.5f) ? 1.0f : 0.0f;
        const float cx = std::clamp(px, 0.0f, float(W - 1)), cy = std::clamp(py, 0.0f, float(H - 1));
        const int x0 = int(cx), y0 = int(cy);
        const int x1 = x0 + 1 < W ? x0 + 1 : W - 1, y1 = y0 + 1 < H ? y0 + 1 : H - 1;
        const float fx = cx - float(x0), fy = cy - float(y0);
        const size_t a00 = size_t(y0) * size_t(W) + size_t(x0), a01 = size_t(y0) * size_t(W) + size_t(x1);
        const size_t a10 = size_t(y1) * size_t(W) + size_t(x0), a11 = size_t(y1) * size_t(W) + size_t(x1);
        auto bil = [&](const float* s) {
          return (s[a00] * (1 - fx) + s[a01] * fx) * (1 - fy) + (s[a10] * (1 - fx) + s[a11] * fx) * fy;
        };
        for (int c = 0; c < 3; ++c) ws.yw.ch(c)[p] = bil(state.ch(c));
        ws.zw[p] = bil(state.ch(3));
      }
    }
  });
  lap(&st.prepare);
  // Features, 4x4 average pooled to quarter resolution (channels last). Per quarter row:
  // 13 features are input planes, 4 are computed per full-res row; each is summed over 4x4.
  ws.feat.resize(size_t(Wq) * size_t(Hq) * kFeatures);
  parallel_rows(Hq, 2, [&](int r0, int r1) {
    std::vector<float> sum(size_t(kFeatures) * size_t(Wq)), tmp(size_t(4) * size_t(W));
    const float* planes[13] = {ws.x.ch(0),  ws.x.ch(1),  ws.x.ch(2),  in.ch(3),   in.ch(4),  in.ch(5),  in.ch(6),
                               in.ch(7),    in.ch(8),    in.ch(10),   ws.yw.ch(0), ws.yw.ch(1), ws.yw.ch(2)};
    for (int qy = r0; qy < r1; ++qy) {
      std::fill(sum.begin(), sum.end(), 0.0f);
      for (int sy = 0; sy < 4; ++sy) {
        const int y = qy * 4 + sy;
        const size_t row = size_t(y) * size_t(W);
        const size_t below = size_t(y + 1 < H ? y + 1 : H - 1) * size_t(W);
        float* valid = tmp.data();
        float* dz = valid + W;
        float* zg = dz + W;
        float* xl2 = zg + W;
        for (int i = 0; i < W; ++i) {
          const size_t p = row + size_t(i);
          const float inv = 1.0f / ws.zc[p];
          const float v = ws.valid[p];
          valid[i] = v;
          const float d = std::abs(ws.zw[p] - z[p]) * inv;
          dz[i] = (d < 1.0f ? d : 1.0f) * v;
          const float zr = z[row + size_t(i + 1 < W ? i + 1 : W - 1)], zd = z[below + size_t(i)];
          const float g = (std::abs(zr - z[p]) + std::abs(zd - z[p])) * inv;
          zg[i] = g < 1.0f ? g : 1.0f;
          const float xl = (ws.x.ch(0)[p] + ws.x.ch(1)[p] + ws.x.ch(2)[p]) / 3.0f;
          xl2[i] = xl * xl;
        }
        // Feature order: x 0-2, albedo 3-5, normal 6-8, roughness 9, yw 10-12, valid 13,
        // dz 14, zg 15, mean(x)^2 16.
        for (int k = 0; k < kFeatures; ++k) {
          const float* src = k < 13 ? planes[k] + row : tmp.data() + size_t(k - 13) * size_t(W);
          float* acc = sum.data() + size_t(k) * size_t(Wq);
          for (int qx = 0; qx < Wq; ++qx) acc[qx] += src[4 * qx] + src[4 * qx + 1] + src[4 * qx + 2] + src[4 * qx + 3];
        }
      }
      float* out = &ws.feat[size_t(qy) * size_t(Wq) * kFeatures];
      for (int qx = 0; qx < Wq; ++qx)
        for (int k = 0; k < kFeatures; ++k) out[size_t(qx) * kFeatures + size_t(k)] = sum[size_t(k) * size_t(Wq) + size_t(qx)] * (1.0f / 16.0f);
    }
  });
  lap(&st.features);
  // The CNN at 1/4 and 1/8 resolution.
  conv_layer(nw.enc1, ws.feat, Wq, Hq, ws.e1, true, ws.padded);
  const int We = Wq / 2, He = Hq / 2;
  ws.pooled.resize(size_t(We) * size_t(He) * 16);
  parallel_rows(He, 4, [&](int r0, int r1) {
  for (int y = r0; y < r1; ++y)
    for (int i = 0; i < We; ++i) {
      const float* a = &ws.e1[(size_t(2 * y) * size_t(Wq) + size_t(2 * i)) * 16];
      const float* b = a + size_t(Wq) * 16;
      float* o = &ws.pooled[(size_t(y) * size_t(We) + size_t(i)) * 16];
      for (int c = 0; c < 16; ++c) o[c] = (a[c] + a[16 + c] + b[c] + b[16 + c]) * 0.25f;
    }
  });
  conv_layer(nw.enc2, ws.pooled, We, He, ws.e2, true, ws.padded);
  conv_layer(nw.enc3, ws.e2, We, He, ws.e3, true, ws.padded);
  ws.cat.resize(size_t(Wq) * size_t(Hq) * 48);
  parallel_rows(Hq, 4, [&](int r0, int r1) {
    for (int y = r0; y < r1; ++y)
      for (int i = 0; i < Wq; ++i) {
        float* c = &ws.cat[(size_t(y) * size_t(Wq) + size_t(i)) * 48];
        std::memcpy(c, &ws.e3[(size_t(y / 2) * size_t(We) + size_t(i / 2)) * 32], 32 * sizeof(float));
        std::memcpy(c + 32, &ws.e1[(size_t(y) * size_t(Wq) + size_t(i)) * 16], 16 * sizeof(float));
      }
  });
  conv_layer(nw.dec1, ws.cat, Wq, Hq, ws.d1, true, ws.padded);
  conv_layer(nw.head, ws.d1, Wq, Hq, ws.o, false, ws.padded);
  // Activations at quarter resolution, planar.
  const size_t Nq = size_t(Wq) * size_t(Hq);
  ws.act.resize(Nq * kOutputs);
  tbb::parallel_for(tbb::blocked_range<size_t>(0, Nq, 2048), [&](const tbb::blocked_range<size_t>& range) {
  for (size_t p = range.begin(); p < range.end(); ++p) {
    const float* v = &ws.o[p * size_t(nw.head.cout)];
    for (int k = 0; k < kOutputs; ++k) {
      const bool gate = k == 0 || k % 4 == 0;  // alpha and the betas: sigmoid; the rest softplus
      const float e = exp_any(gate ? -v[k] : v[k]);
      ws.act[size_t(k) * Nq + p] = gate ? 1.0f / (1.0f + e) : (v[k] > 20.0f ? v[k] : log1p_pos(e));
    }
  }
  });
  lap(&st.cnn);
  // Bilinear x4 upsampling of one activation plane (optionally divided per pixel).
  // Bilinear x4 upsampling (PyTorch's align_corners=False): each quarter-res row is first
  // upsampled horizontally once (Hq x W), then every output row is a lerp of two such rows.
  std::vector<int> c0(static_cast<size_t>(W)), c1(static_cast<size_t>(W));
  std::vector<float> cf(static_cast<size_t>(W));
  for (int i = 0; i < W; ++i) {
    const UpTap tx = up_tap(i, Wq, 0.25f);
    c0[size_t(i)] = tx.i0, c1[size_t(i)] = tx.i1, cf[size_t(i)] = tx.f;
  }
  ws.hrows.resize(size_t(Hq) * size_t(W));
  auto upsample = [&](int channel, float* out, const float* divide) {
    const float* s = &ws.act[size_t(channel) * Nq];
    float* hr = ws.hrows.data();
    parallel_rows(Hq, 4, [&](int r0, int r1) {
      for (int y = r0; y < r1; ++y) {
        const float* a = s + size_t(y) * size_t(Wq);
        float* o = hr + size_t(y) * size_t(W);
        for (int i = 0; i < W; ++i) o[i] = a[c0[size_t(i)]] * (1 - cf[size_t(i)]) + a[c1[size_t(i)]] * cf[size_t(i)];
      }
    });
    parallel_rows(H, 8, [&](int r0, int r1) {
      for (int y = r0; y < r1; ++y) {
        const UpTap ty = up_tap(y, Hq, 0.25f);
        const float* top = hr + size_t(ty.i0) * size_t(W);
        const float* bot = hr + size_t(ty.i1) * size_t(W);
        float* o = out + size_t(y) * size_t(W);
        const float fy = ty.f;
        if (divide) {
          const float* d = divide + size_t(y) * size_t(W);
          for (int i = 0; i < W; ++i) o[i] = (top[i] * (1 - fy) + bot[i] * fy) / d[i];
        } else {
          for (int i = 0; i < W; ++i) o[i] = top[i] * (1 - fy) + bot[i] * fy;
        }
      }
    });
  };
  ws.param.resize(N * 4);
  ensure(ws.xi, W, H, 3);
  ensure(ws.xo, W, H, 3);
  upsample(0, ws.param.data(), nullptr);
  for (int c = 0; c < 3; ++c) {
    const float* x = ws.x.ch(c);
    const float* yw = ws.yw.ch(c);
    float* xi = ws.xi.ch(c);
    for (size_t p = 0; p < N; ++p) xi[p] = x[p] + ws.param[p] * ws.valid[p] * (yw[p] - x[p]);
  }
  lap(&st.temporal);
  // The a-trous levels.
  for (int l = 0; l < kLevels; ++l) {
    float* sc = ws.param.data();
    float* sn = sc + N;
    float* sz = sn + N;
    float* beta = sz + N;
    upsample(1 + 4 * l, sc, nullptr);
    upsample(2 + 4 * l, sn, nullptr);
    upsample(3 + 4 * l, sz, ws.zc.data());
    upsample(4 + 4 * l, beta, nullptr);
    AtrousArgs a;
    for (int c = 0; c < 3; ++c) a.x[c] = ws.xi.ch(c), a.n[c] = in.ch(6 + c), a.out[c] = ws.xo.ch(c);
    a.z = z, a.sc = sc, a.sn = sn, a.sz = sz, a.beta = beta;
    a.width = W, a.height = H, a.dilation = 1 << l;
    parallel_rows(H, 4, [&](int r0, int r1) { atrous_rows(a, r0, r1); });
    std::swap(ws.xi, ws.xo);
  }
  lap(&st.filter);
  ensure(ws.out, W, H, 3);
  ensure(ws.next_state, W, H, 4);
  parallel_rows(H, 8, [&](int r0, int r1) {
    for (int c = 0; c < 3; ++c) {
      const size_t b = size_t(r0) * size_t(W), e = size_t(r1) * size_t(W);
      const float* xi = ws.xi.ch(c);
      const float* alb = in.ch(3 + c);
      float* o = ws.out.ch(c);
      for (size_t p = b; p < e; ++p) {
        const float v = xi[p] > 0.0f ? xi[p] : 0.0f;
        const float a = alb[p] > 0.0f ? alb[p] : 0.0f;
        o[p] = (exp_any(v) - 1.0f) * (a + kAlbedoEps);
      }
      std::memcpy(ws.next_state.ch(c) + b, xi + b, sizeof(float) * (e - b));
    }
    std::memcpy(ws.next_state.ch(3) + size_t(r0) * size_t(W), z + size_t(r0) * size_t(W), sizeof(float) * size_t(r1 - r0) * size_t(W));
  });
  std::swap(state, ws.next_state);
  lap(&st.output);
  return ws.out;
}
