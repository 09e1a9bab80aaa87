// Included by kernels_<isa>.cpp inside namespace kestrel::denoise::KESTREL_ISA_NS.
// Per-pixel loops whose bodies hold a select (the exp, the log, clamps) are written once for
// float and the ISA's vector (core/simd/lanes.inl: for_lanes, atrous_span): GCC's auto-vectoriser
// does those only with AVX-512's masks. The rest are plain loops it vectorises on every ISA.

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

#include "core/simd/lanes.inl"

#include "denoise/kernels_filter.inl"

// ---- The whole network per frame (model.py's forward), with this file's ISA. ----

// Denormals flushed to zero (FTZ + DAZ) for the duration of a task: products of tiny
// filter weights and dark pixels land in the denormal range, where x86 arithmetic is ~100x
// slower; the values involved are far below anything visible.
struct FlushDenormals {
  unsigned saved = _mm_getcsr();
  FlushDenormals() { _mm_setcsr(saved | 0x8040u); }
  ~FlushDenormals() { _mm_setcsr(saved); }
};

template <class F>
static void parallel_rows(int h, int grain, F&& f) {
  parallel_for(0, size_t(h), size_t(grain), [&](size_t begin, size_t end) {
    FlushDenormals ftz;
    f(int(begin), int(end));
  });
}

// The convolutions run on src/nn's kernel of this file's instruction set (bf16 if asked and
// there is one: ws.bf16).
static void conv_layer(const ConvLayer& l, const std::vector<float>& in, int w, int h,
                       std::vector<float>& out, bool relu, Workspace& ws) {
  nn::conv_kernels(kThisIsa, ws.bf16).conv(l, in, w, h, out, relu, ws.padded);
}

static void ensure(Planes& p, int w, int h, int c) {
  if (p.width != w || p.height != h || p.channels != c) p = Planes(w, h, c);
}

#if defined(__AVX512F__)
// A group of kLanes pixels whose bilinear taps (i00, i00 + 1, and a row below) are not
// consecutive but lie within two spans of 2 kLanes pixels (a moving camera: within one row,
// or across two): the spans' starts, the lanes of the second, and each lane's offsets in its
// span.
struct WarpPick {
  int base[2];
  bool two;     // whether there is a second span
  vint second;  // all ones in its lanes
  vint off[2];
};

// Whether the group's taps fit WarpPick (every lane's right and lower taps inside the image,
// both rows' loads inside the N-pixel plane); fills `pick` if so.
static inline bool warp_pick(const int* i00, const int* dx, const int* dy, int W, size_t N,
                             WarpPick& pick) {
  vint v, ddx, ddy;
  std::memcpy(&v, i00, sizeof v), std::memcpy(&ddx, dx, sizeof v), std::memcpy(&ddy, dy, sizeof v);
  if (!all_of((ddx == 1) & (ddy == W))) return false;
  const int span = 2 * kLanes - 2;  // the largest offset whose right tap is in the span
  const int b0 = lane_min(v), top = lane_max(v);
  const vint second = v > b0 + span;
  const bool two = any_of(second);
  const int b1 = two ? lane_min(second ? v : vint{} + top) : b0;
  if (top - b1 > span || size_t(b1) + size_t(W) + 2 * kLanes > N) return false;
  pick.base[0] = b0, pick.base[1] = b1, pick.two = two, pick.second = second;
  pick.off[0] = v - b0, pick.off[1] = v - b1;
  return true;
}

// The bilinear warp of plane s over a WarpPick group (the same operations as the lanes'
// loads: the same values).
static inline vfloat warp_bilinear(const float* s, const WarpPick& pk, int W, vfloat x1,
                                   vfloat y1) {
  // Tap (row 0 or W, column 0 or 1) of every lane: from its span.
  auto tap = [&](int row, int col) {
    auto pick = [&](int k) {
      const float* r = s + pk.base[k] + row;
      return perm2(ld<vfloat>(r), ld<vfloat>(r + kLanes), pk.off[k] + col);
    };
    const vfloat a = pick(0);
    return pk.two ? (pk.second ? pick(1) : a) : a;
  };
  const vfloat top = tap(0, 0) * (1.0f - x1) + tap(0, 1) * x1;
  const vfloat bot = tap(W, 0) * (1.0f - x1) + tap(W, 1) * x1;
  return top * (1.0f - y1) + bot * y1;
}
#endif

// model.py's demodulation(): albedo + EPS, or 1 where every channel is below kBlackAlbedo.
template <class T>
static inline T demodulation(T a0, T a1, T a2, T a) {
  const T zero = T{} + 0.0f;
  const T m = a0 > a1 ? a0 : a1, top = m > a2 ? m : a2;
  return top < kBlackAlbedo ? zero + 1.0f : (a > zero ? a : zero) + kAlbedoEps;
}

#include "denoise/kernels_history.inl"

// 1 where every channel of the albedo is below kBlackAlbedo (not demodulated), else 0;
// returns whether the row has any.
static bool black_row(int n, const float* a0, const float* a1, const float* a2, float* k) {
  float any = 0.0f;
  for (int i = 0; i < n; ++i) {
    k[i] = black_albedo(a0[i], a1[i], a2[i]) ? 1.0f : 0.0f;
    any = any > k[i] ? any : k[i];
  }
  return any > 0.0f;
}

// d = demodulation, x = max(colour, 0) / d, g = log(1 + x).
static void demodulate_row(int n, const float* col, const float* a0, const float* a1,
                           const float* a2, const float* alb, float* d, float* x, float* g) {
  for_lanes(n, [&](auto tag, int i) {
    using T = decltype(tag);
    const T zero = T{} + 0.0f;
    const T dm = demodulation(ld<T>(a0 + i), ld<T>(a1 + i), ld<T>(a2 + i), ld<T>(alb + i));
    const T c = ld<T>(col + i), v = c > zero ? c : zero, xv = v / dm;
    st(d + i, dm), st(x + i, xv), st(g + i, vlog1p_pos(xv));
  });
}

// xi = x + a (yw - x), g = log(1 + max(xi, 0)).
static void blend_row(int n, const float* x, const float* yw, const float* a, float* xi, float* g) {
  for_lanes(n, [&](auto tag, int i) {
    using T = decltype(tag);
    const T zero = T{} + 0.0f, xv = ld<T>(x + i);
    const T v = xv + ld<T>(a + i) * (ld<T>(yw + i) - xv);
    st(xi + i, v), st(g + i, vlog1p_pos(v > zero ? v : zero));
  });
}

// exp(x) for x in [-36, 88] (0 below, clamped above).
template <class T>
static inline T exp_any(T x) {
  x = x > 88.0f ? T{} + 88.0f : x;
  return vexp_neg(x - 44.0f) * 1.2851600e19f;  // e^44, so both halves stay in range
}

static const Planes& network(const NeuralWeights& nw, const Planes& in, Planes& state,
                             bool recurrent, Workspace& ws, StageTimes* times) {
  using clock = std::chrono::steady_clock;
  auto t = clock::now();
  auto lap = [&](double* slot) {
    const auto now = clock::now();
    if (times) *slot = std::chrono::duration<double, std::milli>(now - t).count();
    t = now;
  };
  StageTimes dummy;
  StageTimes& stage = times ? *times : dummy;
  const int W = in.width, H = in.height;
  const size_t N = size_t(W) * size_t(H);
  const int Wq = W / 4, Hq = H / 4;
  ensure(ws.x, W, H, 3);
  ensure(ws.xlin, W, H, 3);
  ensure(ws.demod, W, H, 3);
  // The black flags go straight into the next state (channel 5), where they are kept.
  ensure(ws.next_state, W, H, kStateChannels);
  float* const black = ws.next_state.ch(5);
  ensure(ws.yw, W, H, 3);
  ws.zw.resize(N), ws.nw.resize(N), ws.kw.resize(N), ws.valid.resize(N), ws.zc.resize(N);
  ws.black_rows.resize(size_t(H));
  const float* z = in.ch(9);
  const bool have_state =
      recurrent && state.width == W && state.height == H && state.channels == kStateChannels;
  // x = log1p(demodulated colour); the previous output and depth warped by the motion.
  parallel_rows(H, 8, [&](int r0, int r1) {
    // Per thread, kept from task to task and frame to frame (a row's taps: ~90 tasks a 720p
    // frame each allocated and zeroed its own).
    thread_local struct {
      std::vector<int> idx, dx;
      std::vector<int> dy;
      std::vector<float> fx, fy;
      std::vector<uint8_t> run;
#if defined(__AVX512F__)
      std::vector<WarpPick> pick;
#endif
    } scratch;
    if (have_state) {
      scratch.idx.resize(size_t(W)), scratch.dx.resize(size_t(W)), scratch.dy.resize(size_t(W));
      scratch.fx.resize(size_t(W)), scratch.fy.resize(size_t(W));
      scratch.run.resize(size_t(W / kLanes) + 1);
#if defined(__AVX512F__)
      scratch.pick.resize(size_t(W / kLanes) + 1);
#endif
    }
    for (int y = r0; y < r1; ++y) {
      const size_t row = size_t(y) * size_t(W);
      for (int c = 0; c < 3; ++c) {
        const float* col = in.ch(c) + row;
        const float *a0 = in.ch(3) + row, *a1 = in.ch(4) + row, *a2 = in.ch(5) + row;
        const float* alb = in.ch(3 + c) + row;
        float* xo = ws.x.ch(c) + row;
        float* xl = ws.xlin.ch(c) + row;
        float* dm = ws.demod.ch(c) + row;
        demodulate_row(W, col, a0, a1, a2, alb, dm, xl, xo);
      }
      ws.black_rows[size_t(y)] =
          black_row(W, in.ch(3) + row, in.ch(4) + row, in.ch(5) + row, black + row);
      for (int i = 0; i < W; ++i)
        ws.zc[row + size_t(i)] = z[row + size_t(i)] > kMinDepth ? z[row + size_t(i)] : kMinDepth;
      if (!have_state) {
        for (int c = 0; c < 3; ++c)
          std::memcpy(ws.yw.ch(c) + row, ws.xlin.ch(c) + row, sizeof(float) * size_t(W));
        std::memcpy(ws.zw.data() + row, z + row, sizeof(float) * size_t(W));
        std::fill(ws.valid.begin() + std::ptrdiff_t(row),
                  ws.valid.begin() + std::ptrdiff_t(row + size_t(W)), 0.0f);
        std::fill(ws.nw.begin() + std::ptrdiff_t(row),
                  ws.nw.begin() + std::ptrdiff_t(row + size_t(W)), 0.0f);
        continue;
      }
      // Bilinear taps of p + motion (clamped), then the four planes gathered.
      int* i00 = scratch.idx.data();
      float* fx = scratch.fx.data();
      float* fy = scratch.fy.data();
      int* dx = scratch.dx.data();
      int* dy = scratch.dy.data();
      const float* mx = in.ch(11) + row;
      const float* my = in.ch(12) + row;
      float* valid = ws.valid.data() + row;
      for_lanes(W, [&](auto tag, int i) {
        using T = decltype(tag);
        using I = decltype(vtrunc(tag));
        const T zero = T{} + 0.0f, one = T{} + 1.0f;
        const T px = vindex(tag, i) + ld<T>(mx + i), py = float(y) + ld<T>(my + i);
        const auto in =
            (px >= -0.5f) & (px <= float(W) - 0.5f) & (py >= -0.5f) & (py <= float(H) - 0.5f);
        st(valid + i, in ? one : zero);
        const T cx = px < 0.0f ? zero : (px > float(W - 1) ? zero + float(W - 1) : px);
        const T cy = py < 0.0f ? zero : (py > float(H - 1) ? zero + float(H - 1) : py);
        const I x0 = vtrunc(cx), y0 = vtrunc(cy);
        st(fx + i, cx - vfloat_of(x0)), st(fy + i, cy - vfloat_of(y0));
        sti(dx + i, x0 + 1 < W ? I{} + 1 : I{});
        sti(dy + i, y0 + 1 < H ? I{} + W : I{});
        sti(i00 + i, y0 * W + x0);
      });
      // Groups of kLanes pixels whose taps are kLanes consecutive pixels (the same whole-pixel
      // motion, nearly everywhere) read them with vector loads; the others pixel by pixel.
      uint8_t* run = scratch.run.data();
      for (int g = 0; g + kLanes <= W; g += kLanes) {
        bool same = true;
        for (int l = 0; l < kLanes; ++l)
          same &= (i00[g + l] == i00[g] + l) & (dx[g + l] == 1) & (dy[g + l] == dy[g]);
        run[g / kLanes] = same;
#if defined(__AVX512F__)
        if (!same)
          run[g / kLanes] =
              warp_pick(i00 + g, dx + g, dy + g, W, N, scratch.pick[g / kLanes]) ? 2 : 0;
#endif
      }
      auto gather4 = [&](const float* s, float* out) {
        auto lanes = [&](auto tag, int i) {
          using T = decltype(tag);
          const float* a = s + i00[i];
          const T x1 = ld<T>(fx + i), y1 = ld<T>(fy + i);
          const T top = ld<T>(a) * (1.0f - x1) + ld<T>(a + dx[i]) * x1;
          const T bot = ld<T>(a + dy[i]) * (1.0f - x1) + ld<T>(a + dy[i] + dx[i]) * x1;
          st(out + i, top * (1.0f - y1) + bot * y1);
        };
        int i = 0;
        for (; i + kLanes <= W; i += kLanes)
          if (run[i / kLanes] == 1)
            lanes(vfloat{}, i);
#if defined(__AVX512F__)
          else if (run[i / kLanes] == 2)
            st(out + i, warp_bilinear(s, scratch.pick[i / kLanes], W, ld<vfloat>(fx + i),
                                      ld<vfloat>(fy + i)));
#endif
          else
            for (int l = 0; l < kLanes; ++l) lanes(0.0f, i + l);
        for (; i < W; ++i) lanes(0.0f, i);
      };
      for (int c = 0; c < 3; ++c) gather4(state.ch(c), ws.yw.ch(c) + row);
      gather4(state.ch(3), ws.zw.data() + row);
      gather4(state.ch(4), ws.nw.data() + row);
      gather4(state.ch(5), ws.kw.data() + row);
      // Disocclusion: the history's depth more than 10 % off rejects it (and its length), as
      // does a tap demodulated otherwise than this pixel (its warped black flag differs).
      const float* zw = ws.zw.data() + row;
      const float* zc = ws.zc.data() + row;
      const float* zr = z + row;
      const float* kw = ws.kw.data() + row;
      const float* bk = black + row;
      float* nw = ws.nw.data() + row;
      for_lanes(W, [&](auto tag, int i) {
        using T = decltype(tag);
        const auto same = (vabs(ld<T>(zw + i) - ld<T>(zr + i)) <= kDisoccluded * ld<T>(zc + i)) &
                          (vabs(ld<T>(kw + i) - ld<T>(bk + i)) < 1e-3f);
        const T v = same ? ld<T>(valid + i) : T{} + 0.0f;
        st(valid + i, v), st(nw + i, ld<T>(nw + i) * v);
      });
    }
  });
  block_bounds(ws, W, H);
  if (have_state) clamp_history(ws, W, H);
  lap(&stage.prepare);
  // Features, 4x4 average pooled to quarter resolution (channels last). Per quarter row:
  // 13 features are (warped) planes, 5 are computed per full-res row; each is summed over 4x4.
  ws.feat.resize(size_t(Wq) * size_t(Hq) * kFeatures);
  parallel_rows(Hq, 2, [&](int r0, int r1) {
    std::vector<float> sum(size_t(kFeatures) * size_t(Wq)), tmp(size_t(8) * size_t(W));
    const float* planes[10] = {ws.x.ch(0), ws.x.ch(1), ws.x.ch(2), in.ch(3), in.ch(4),
                               in.ch(5),   in.ch(6),   in.ch(7),   in.ch(8), in.ch(10)};
    for (int qy = r0; qy < r1; ++qy) {
      std::fill(sum.begin(), sum.end(), 0.0f);
      for (int sy = 0; sy < 4; ++sy) {
        const int y = qy * 4 + sy;
        const size_t row = size_t(y) * size_t(W);
        const size_t below = size_t(y + 1 < H ? y + 1 : H - 1) * size_t(W);
        float* ywl = tmp.data();  // 3 rows: log(1 + warped previous irradiance)
        float* valid = ywl + 3 * size_t(W);
        float* dz = valid + W;
        float* zg = dz + W;
        float* xl2 = zg + W;
        float* ninv = xl2 + W;
        // Pixel i (i .. i + lanes - 1), its right neighbour at column r.
        auto feature_lanes = [&](auto tag, int i, int r) {
          using T = decltype(tag);
          const size_t p = row + size_t(i);
          const T zero = T{} + 0.0f, one = zero + 1.0f;
          for (int c = 0; c < 3; ++c) {
            const T v = ld<T>(ws.yw.ch(c) + p);
            st(ywl + size_t(c) * size_t(W) + size_t(i), vlog1p_pos(v > zero ? v : zero));
          }
          const T inv = 1.0f / ld<T>(ws.zc.data() + p), zp = ld<T>(z + p);
          const T v = ld<T>(ws.valid.data() + p);
          st(valid + i, v);
          const T d = vabs(ld<T>(ws.zw.data() + p) - zp) * inv;
          st(dz + i, (d < one ? d : one) * v);
          const T zr = ld<T>(z + row + size_t(r)), zd = ld<T>(z + below + size_t(i));
          const T g = (vabs(zr - zp) + vabs(zd - zp)) * inv;
          st(zg + i, g < one ? g : one);
          const T xl =
              (ld<T>(ws.x.ch(0) + p) + ld<T>(ws.x.ch(1) + p) + ld<T>(ws.x.ch(2) + p)) / 3.0f;
          st(xl2 + i, xl * xl);
          st(ninv + i, 1.0f / (1.0f + ld<T>(ws.nw.data() + p)));
        };
        // The last column's right neighbour is itself: vectors stop short of it.
        for_lanes(W - 1, [&](auto tag, int i) { feature_lanes(tag, i, i + 1); });
        feature_lanes(0.0f, W - 1, W - 1);
        // Feature order: x 0-2, albedo 3-5, normal 6-8, roughness 9, yw 10-12, valid 13,
        // dz 14, zg 15, mean(x)^2 16, 1 / (1 + nw) 17.
        for (int k = 0; k < kFeatures; ++k) {
          const float* src = k < 10 ? planes[k] + row : tmp.data() + size_t(k - 10) * size_t(W);
          float* acc = sum.data() + size_t(k) * size_t(Wq);
          for (int qx = 0; qx < Wq; ++qx)
            acc[qx] += src[4 * qx] + src[4 * qx + 1] + src[4 * qx + 2] + src[4 * qx + 3];
        }
      }
      float* out = &ws.feat[size_t(qy) * size_t(Wq) * kFeatures];
      for (int qx = 0; qx < Wq; ++qx)
        for (int k = 0; k < kFeatures; ++k)
          out[size_t(qx) * kFeatures + size_t(k)] =
              sum[size_t(k) * size_t(Wq) + size_t(qx)] * (1.0f / 16.0f);
    }
  });
  lap(&stage.features);
  // The CNN at 1/4 and 1/8 resolution.
  conv_layer(nw.enc1, ws.feat, Wq, Hq, ws.e1, true, ws);
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
  conv_layer(nw.enc2, ws.pooled, We, He, ws.e2, true, ws);
  conv_layer(nw.enc3, ws.e2, We, He, ws.e3, true, ws);
  ws.cat.resize(size_t(Wq) * size_t(Hq) * 48);
  parallel_rows(Hq, 4, [&](int r0, int r1) {
    for (int y = r0; y < r1; ++y)
      for (int i = 0; i < Wq; ++i) {
        float* c = &ws.cat[(size_t(y) * size_t(Wq) + size_t(i)) * 48];
        std::memcpy(c, &ws.e3[(size_t(y / 2) * size_t(We) + size_t(i / 2)) * 32],
                    32 * sizeof(float));
        std::memcpy(c + 32, &ws.e1[(size_t(y) * size_t(Wq) + size_t(i)) * 16], 16 * sizeof(float));
      }
  });
  conv_layer(nw.dec1, ws.cat, Wq, Hq, ws.d1, true, ws);
  conv_layer(nw.head, ws.d1, Wq, Hq, ws.o, false, ws);
  // Activations at quarter resolution, planar.
  const size_t Nq = size_t(Wq) * size_t(Hq);
  ws.act.resize(Nq * kOutputs);
  const size_t ostride = size_t(nw.head.cout);
  parallel_for(0, Nq, 4096, [&](size_t range_begin, size_t range_end) {
    FlushDenormals ftz;
    for (int k = 0; k < kOutputs; ++k) {
      const float* v = ws.o.data() + size_t(k);
      float* out = ws.act.data() + size_t(k) * Nq;
      const bool sigmoid = k == 0 || k % 4 == 0;  // alpha and the betas (kappa, 17: softplus)
      // The edge-stopping strengths and kappa: softplus (+ the floors of sn, sz).
      const float floor = k < kOutputs - 1 && k % 4 == 2
                              ? kMinNormalStop
                              : (k < kOutputs - 1 && k % 4 == 3 ? kMinDepthStop : 0.0f);
      for_lanes(int(range_end - range_begin), [&](auto tag, int j) {
        using T = decltype(tag);
        const size_t p = range_begin + size_t(j);
        float col[sizeof(T) / sizeof(float)];  // the map's channel: strided in ws.o
        for (size_t l = 0; l < sizeof(T) / sizeof(float); ++l) col[l] = v[(p + l) * ostride];
        const T x = ld<T>(col);
        st(out + p, sigmoid ? 1.0f / (1.0f + exp_any(T{} - x))
                            : (x > 20.0f ? x : vlog1p_pos(exp_any(x))) + floor);
      });
    }
  });
  lap(&stage.cnn);
  // Bilinear x4 upsampling (PyTorch's align_corners=False), separable: every activation
  // map's quarter-res rows are upsampled horizontally once (Hq x W per map); output rows
  // lerp two of them, inside the temporal blend and the a-trous filter (no full-res maps).
  std::vector<int> c0(static_cast<size_t>(W)), c1(static_cast<size_t>(W));
  std::vector<float> cf(static_cast<size_t>(W));
  for (int i = 0; i < W; ++i) {
    const UpTap tx = up_tap(i, Wq, 0.25f);
    c0[size_t(i)] = tx.i0, c1[size_t(i)] = tx.i1, cf[size_t(i)] = tx.f;
  }
  const size_t hplane = size_t(Hq) * size_t(W);
  ws.hrows.resize(hplane * kOutputs);
  parallel_rows(Hq * kOutputs, 4, [&](int r0, int r1) {
    for (int r = r0; r < r1; ++r) {
      const int k = r / Hq, y = r % Hq;
      const float* a = &ws.act[size_t(k) * Nq + size_t(y) * size_t(Wq)];
      float* o = ws.hrows.data() + size_t(k) * hplane + size_t(y) * size_t(W);
      for (int i = 0; i < W; ++i)
        o[i] = a[c0[size_t(i)]] * (1 - cf[size_t(i)]) + a[c1[size_t(i)]] * cf[size_t(i)];
    }
  });
  ensure(ws.xi, W, H, 3);
  ensure(ws.xo, W, H, 3);
  ensure(ws.lg, W, H, 3);
  // This frame's fireflies cut (ws.xo) and their cut energy spread over their windows, then
  // the temporal blend: r0 = xc + a (yw - xc),
  // a = alpha nw / (1 + nw), into the filter's input (ws.xi) with log(1 + r0) its first
  // guide (ws.lg); the new history length n = min(1 / (1 - a), kMaxHistory) into the state
  // (whose irradiance is the first filter level's output, copied below).
  firefly_clamp(ws, W, H, in.image_width > 0 ? in.image_width : W,
                in.image_height > 0 ? in.image_height : H);
  redistribute(ws, W, H);
  parallel_rows(H, 8, [&](int r0, int r1) {
    std::vector<float> a(static_cast<size_t>(W));
    for (int y = r0; y < r1; ++y) {
      const UpTap ty = up_tap(y, Hq, 0.25f);
      const float* top = ws.hrows.data() + size_t(ty.i0) * size_t(W);
      const float* bot = ws.hrows.data() + size_t(ty.i1) * size_t(W);
      const size_t row = size_t(y) * size_t(W);
      const float* nw = ws.nw.data() + row;
      float* n = ws.next_state.ch(4) + row;
      for (int i = 0; i < W; ++i) {
        const float alpha = top[i] * (1 - ty.f) + bot[i] * ty.f;
        a[size_t(i)] = alpha * (nw[i] / (1.0f + nw[i]));
        const float len = 1.0f / (1.0f - a[size_t(i)]);
        n[i] = len < kMaxHistory ? len : kMaxHistory;
      }
      for (int c = 0; c < 3; ++c) {
        const float* x = ws.xo.ch(c) + row;
        const float* yw = ws.yw.ch(c) + row;
        blend_row(W, x, yw, a.data(), ws.xi.ch(c) + row, ws.lg.ch(c) + row);
      }
    }
  });
  lap(&stage.temporal);
  // The a-trous levels; each writes the next one's guide (the first guide: firefly_clamp).
  ensure(ws.lg2, W, H, 3);
  for (int l = 0; l < kLevels; ++l) {
    AtrousArgs a;
    for (int c = 0; c < 3; ++c) {
      a.x[c] = ws.xi.ch(c), a.g[c] = ws.lg.ch(c), a.n[c] = in.ch(6 + c), a.out[c] = ws.xo.ch(c);
      a.gout[c] = l + 1 < kLevels ? ws.lg2.ch(c) : nullptr;
    }
    a.z = z, a.black = black, a.black_rows = ws.black_rows.data();
    for (int k = 0; k < 4; ++k) a.param[k] = ws.hrows.data() + size_t(1 + 4 * l + k) * hplane;
    a.param_rows = Hq;
    a.width = W, a.height = H, a.dilation = 1 << l;
    parallel_rows(H, 4, [&](int r0, int r1) { atrous_rows(a, r0, r1); });
    std::swap(ws.xi, ws.xo);
    if (l == 0)  // the first level's output is the next frame's history (as SVGF's)
      parallel_rows(H, 8, [&](int r0, int r1) {
        const size_t b = size_t(r0) * size_t(W), n = size_t(r1 - r0) * size_t(W);
        for (int c = 0; c < 3; ++c)
          std::memcpy(ws.next_state.ch(c) + b, ws.xi.ch(c) + b, sizeof(float) * n);
      });
    std::swap(ws.lg, ws.lg2);
  }
  lap(&stage.filter);
  // The output: model.py's output_clamp (a pixel brighter than all but one of its neighbours
  // inside the image and than its valid history of two frames or more comes out at that
  // level), times d.
  ensure(ws.out, W, H, 3);
  const int image_w = in.image_width > 0 ? in.image_width : W;
  const int image_h = in.image_height > 0 ? in.image_height : H;
  parallel_rows(H, 8, [&](int r0, int r1) {
    for (int y = r0; y < r1; ++y) {
      const size_t row = size_t(y) * size_t(W);
      const bool inner_row = y >= 1 && y + 1 < image_h;
      const float* n = ws.nw.data() + row;  // 0 where the history is not valid
      for (int c = 0; c < 3; ++c) {
        const float* x = ws.xi.ch(c);
        const float* b = x + row;
        const float *a = b - (y >= 1 ? W : 0), *d = b + (y + 1 < H ? W : 0);
        const float* yw = ws.yw.ch(c) + row;
        const float* dm = ws.demod.ch(c) + row;
        float* o = ws.out.ch(c) + row;
        auto checked = [&](int i) {
          float top1, top2;
          neighbours_top2_checked(x, W, i, y, image_w, image_h, top1, top2);
          o[i] = output_cut(b[i], top2, yw[i], n[i], dm[i]);
        };
        const int i1 = inner_row ? std::min(image_w - 1, W) : 0;
        if (i1 > 0) checked(0);
        if (i1 > 1) output_row(1, i1, a, b, d, yw, n, dm, o);
        for (int i = i1 > 0 ? i1 : 0; i < W; ++i) checked(i);
      }
    }
    std::memcpy(ws.next_state.ch(3) + size_t(r0) * size_t(W), z + size_t(r0) * size_t(W),
                sizeof(float) * size_t(r1 - r0) * size_t(W));
  });
  std::swap(state, ws.next_state);
  lap(&stage.output);
  return ws.out;
}
