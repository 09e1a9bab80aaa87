// Included by conv_<isa>.cpp inside namespace kestrel::nn::<isa>_ns (their own -m flags).

// Denormals flushed to zero (FTZ + DAZ) for the duration of a task (see denoise/kernels.inl).
struct FlushDenormals {
  unsigned saved = _mm_getcsr();
  FlushDenormals() { _mm_setcsr(saved | 0x8040u); }
  ~FlushDenormals() { _mm_setcsr(saved); }
};

// Channels-last convolution for cout a multiple of 16, on an input zero-padded by one pixel
// on every side and to a multiple of 8 columns: blocks of kPx output pixels x 16 output
// channels held in registers, each weight vector feeding kPx FMAs. The 16 channels are
// 16 / kLanes vectors of the ISA's own width (GCC lowers a 64-byte vector type badly where
// the registers are narrower: through the stack), and kPx is what fits the ISA's 16 or 32
// registers with the weights and a broadcast. Every output sums its taps in the same order
// whatever kPx and kLanes are.
#if defined(__AVX512F__)
static constexpr int kLanes = 16, kPx = 8;
#elif defined(__AVX__)
static constexpr int kLanes = 8, kPx = 4;
#else
static constexpr int kLanes = 4, kPx = 2;
#endif
static constexpr int kParts = 16 / kLanes;
typedef float VN __attribute__((vector_size(4 * kLanes)));

// Output rows [row0, row1), 16-channel blocks [cb0, cb1) of cout, each computed with P of
// its kParts vectors (P < kParts: the block's last channels are zeros in the weights and the
// bias, a head whose outputs do not fill the block; they are written as zeros). With fewer
// vectors per pixel more pixels fit the registers: kPx * kParts / P.
template <int P>
static void conv_rows_padded(const ConvArgs& a, const float* padded, int row0, int row1, int cb0,
                             int cb1) {
  constexpr int Px = kPx * kParts / P;
  const int w = a.width, cin = a.cin, cout = a.cout, k = a.ksize, r = k / 2;
  const int wp = (w + 7) / 8 * 8, pw = wp + 2;
  for (int y = row0; y < row1; ++y)
    for (int x0 = 0; x0 < w; x0 += Px)
      for (int cb = cb0; cb < cb1; cb += 16) {
        VN acc[Px][P];
#pragma GCC unroll 4
        for (int j = 0; j < P; ++j) {
          VN bias;
          __builtin_memcpy(&bias, a.bias + cb + j * kLanes, sizeof bias);
#pragma GCC unroll 8
          for (int b = 0; b < Px; ++b) acc[b][j] = bias;
        }
        for (int ky = 0; ky < k; ++ky)
          for (int kx = 0; kx < k; ++kx) {
            const float* in =
                padded +
                (size_t(y + ky + 1 - r) * size_t(pw) + size_t(x0 + kx + 1 - r)) * size_t(cin);
            const float* wk =
                a.weights + size_t(ky * k + kx) * size_t(cin) * size_t(cout) + size_t(cb);
            for (int ci = 0; ci < cin; ++ci) {
              VN wv[P];
#pragma GCC unroll 4
              for (int j = 0; j < P; ++j)
                __builtin_memcpy(&wv[j], wk + size_t(ci) * size_t(cout) + size_t(j * kLanes),
                                 sizeof(VN));
#pragma GCC unroll 8
              for (int b = 0; b < Px; ++b) {
                const float v = in[size_t(b) * size_t(cin) + size_t(ci)];
#pragma GCC unroll 4
                for (int j = 0; j < P; ++j) acc[b][j] += v * wv[j];
              }
            }
          }
        const VN zero = {};
#pragma GCC unroll 8
        for (int b = 0; b < Px; ++b) {
          if (x0 + b >= w) break;
          float* o = a.out + (size_t(y) * size_t(w) + size_t(x0 + b)) * size_t(cout) + size_t(cb);
#pragma GCC unroll 4
          for (int j = 0; j < P; ++j) {
            const VN v = a.relu ? (acc[b][j] > zero ? acc[b][j] : zero) : acc[b][j];
            __builtin_memcpy(o + j * kLanes, &v, sizeof v);
          }
          for (int j = P; j < kParts; ++j) __builtin_memcpy(o + j * kLanes, &zero, sizeof zero);
        }
      }
}

// Every output block with all its vectors, the last with as few as its outputs need.
static void conv_rows_padded(const ConvArgs& a, int outputs, const float* padded, int row0,
                             int row1) {
  const int last = (outputs - 1) / 16 * 16, used = (outputs - last + kLanes - 1) / kLanes;
  if (last > 0) conv_rows_padded<kParts>(a, padded, row0, row1, 0, last);
  switch (used) {
#if !defined(__AVX512F__)
    case 1:
      conv_rows_padded<1>(a, padded, row0, row1, last, last + 16);
      break;
#endif
#if !defined(__AVX__)
    case 2:
      conv_rows_padded<2>(a, padded, row0, row1, last, last + 16);
      break;
#endif
    default:
      conv_rows_padded<kParts>(a, padded, row0, row1, last, last + 16);
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
  parallel_for(0, size_t(h), 8, [&](size_t begin, size_t end) {
    for (int y = int(begin); y < int(end); ++y) {
      float* dst = &out[size_t(y + 1) * row_floats];
      std::fill(dst, dst + c, 0.0f);
      std::memcpy(dst + c, in + size_t(y) * size_t(w) * size_t(c),
                  sizeof(float) * size_t(w) * size_t(c));
      std::fill(dst + size_t(w + 1) * size_t(c), dst + row_floats, 0.0f);
    }
  });
}

[[maybe_unused]] static void conv_layer(const ConvLayer& l, const std::vector<float>& in, int w,
                                        int h, std::vector<float>& out, bool relu,
                                        std::vector<float>& scratch) {
  out.resize(size_t(w) * size_t(h) * size_t(l.cout));
  ConvArgs a;
  a.in = in.data(), a.weights = l.weights.data(), a.bias = l.bias.data(), a.out = out.data();
  a.width = w, a.height = h, a.cin = l.cin, a.cout = l.cout, a.ksize = l.ksize, a.relu = relu;
  pad_for_conv(in.data(), w, h, l.cin,
               scratch);  // l.cout is a multiple of 16 (NeuralWeights::load)
  parallel_for(0, size_t(h), 2, [&](size_t r0, size_t r1) {
    FlushDenormals ftz;
    conv_rows_padded(a, l.outputs, scratch.data(), int(r0), int(r1));
  });
}

#if defined(__AVX512BF16__)
// ---- bf16 (AVX-512 BF16): inputs and weights rounded to bf16, products summed in f32 ----
// vdpbf16ps adds, to each of 16 f32 lanes, the products of a pair of bf16 in each operand: a
// lane is an output channel, a pair two input channels. So the padded input holds each
// pixel's channels as bf16 pairs (cp = ceil(cin / 2) slots of 32 bits, the odd channel's
// partner 0) and the weights [ky][kx][pair][cout] a pair per output channel; one broadcast
// pair of a pixel and one weight vector give 32 multiply-adds, twice the f32 kernel's per
// instruction. Slots are stored in float storage (read back as floats and cast, so no type
// punning through pointers). Rounding is to nearest even (vcvtneps2bf16); the products of
// bf16 are exact in f32 and vdpbf16ps sums them in f32 with denormals flushed, so results
// differ from the f32 kernel's by the inputs' and weights' rounding (2^-9 relative) alone.

// n floats of src as n bf16 in dst (n / 2 slots; an odd n's last slot half-written).
static void to_bf16(const float* src, size_t n, float* dst) {
  size_t i = 0;
  for (; i + 16 <= n; i += 16)
    _mm256_storeu_si256(reinterpret_cast<__m256i*>(reinterpret_cast<uint16_t*>(dst) + i),
                        reinterpret_cast<__m256i>(_mm512_cvtneps_pbh(_mm512_loadu_ps(src + i))));
  if (i < n) {
    const __mmask16 m = __mmask16((1u << (n - i)) - 1u);
    _mm256_mask_storeu_epi16(
        reinterpret_cast<uint16_t*>(dst) + i, m,
        reinterpret_cast<__m256i>(_mm512_cvtneps_pbh(_mm512_maskz_loadu_ps(m, src + i))));
  }
}

// The layer's weights as bf16 pairs, [ky][kx][pair][cout] (an odd cin's last pair ends in 0).
static void bf16_weights(const ConvLayer& l, float* out) {
  const int cp = (l.cin + 1) / 2, taps = l.ksize * l.ksize;
  std::vector<float> pair(size_t(2 * l.cout));
  for (int t = 0; t < taps; ++t)
    for (int p = 0; p < cp; ++p) {
      for (int co = 0; co < l.cout; ++co)
        for (int h = 0; h < 2; ++h) {
          const int ci = 2 * p + h;
          pair[size_t(2 * co + h)] =
              ci < l.cin ? l.weights[(size_t(t) * size_t(l.cin) + size_t(ci)) * size_t(l.cout) +
                                     size_t(co)]
                         : 0.0f;
        }
      to_bf16(pair.data(), pair.size(),
              out + (size_t(t) * size_t(cp) + size_t(p)) * size_t(l.cout));
    }
}

// Pixels per block in registers: 16 independent accumulators, enough to cover vdpbf16ps's
// latency at full issue rate (the f32 kernel's 8 measured the same on the Zen 5 host).
static constexpr int kPxBf16 = 16;
static int padded_width_bf16(int w) {
  return (w + kPxBf16 - 1) / kPxBf16 * kPxBf16 + 2;
}

// pad_for_conv's layout with bf16 pairs, rows padded to a multiple of kPxBf16 pixels: (h + 2)
// rows of pw pixels of cp slots from `out`.
static void pad_for_conv_bf16(const float* in, int w, int h, int c, float* out) {
  const int cp = (c + 1) / 2, pw = padded_width_bf16(w);
  const size_t row_slots = size_t(pw) * size_t(cp);
  std::fill(out, out + row_slots, 0.0f);
  std::fill(out + row_slots * size_t(h + 1), out + row_slots * size_t(h + 2), 0.0f);
  parallel_for(0, size_t(h), 8, [&](size_t begin, size_t end) {
    for (int y = int(begin); y < int(end); ++y) {
      float* dst = out + size_t(y + 1) * row_slots;
      const float* src = in + size_t(y) * size_t(w) * size_t(c);
      std::fill(dst, dst + cp, 0.0f);
      if (c % 2 == 0) {
        to_bf16(src, size_t(w) * size_t(c), dst + cp);
      } else {
        // Per pixel, 16 channels at a time; the last chunk's store takes the 0 after the
        // last channel (the masked load's zero lane).
        for (int x = 0; x < w; ++x) {
          uint16_t* d = reinterpret_cast<uint16_t*>(dst + size_t(x + 1) * size_t(cp));
          const float* p = src + size_t(x) * size_t(c);
          for (int i = 0; i < c; i += 16) {
            const __mmask16 load = __mmask16((1u << std::min(16, c - i)) - 1u),
                            store = __mmask16((1u << std::min(16, c + 1 - i)) - 1u);
            _mm256_mask_storeu_epi16(
                d + i, store,
                reinterpret_cast<__m256i>(_mm512_cvtneps_pbh(_mm512_maskz_loadu_ps(load, p + i))));
          }
        }
      }
      std::fill(dst + size_t(w + 1) * size_t(cp), dst + row_slots, 0.0f);
    }
  });
}

// Output rows [row0, row1), every 16-channel block, kPxBf16 pixels at a time in registers.
static void conv_rows_bf16(const ConvArgs& a, const float* padded, const float* wts, int row0,
                           int row1) {
  constexpr int kPx = kPxBf16;
  const int w = a.width, cout = a.cout, k = a.ksize, r = k / 2, cp = (a.cin + 1) / 2;
  const int pw = padded_width_bf16(w);
  for (int y = row0; y < row1; ++y)
    for (int x0 = 0; x0 < w; x0 += kPx)
      for (int cb = 0; cb < cout; cb += 16) {
        __m512 acc[kPx];
        const __m512 bias = _mm512_loadu_ps(a.bias + cb);
#pragma GCC unroll 16
        for (int b = 0; b < kPx; ++b) acc[b] = bias;
        for (int ky = 0; ky < k; ++ky)
          for (int kx = 0; kx < k; ++kx) {
            const float* in =
                padded +
                (size_t(y + ky + 1 - r) * size_t(pw) + size_t(x0 + kx + 1 - r)) * size_t(cp);
            const float* wk = wts + size_t(ky * k + kx) * size_t(cp) * size_t(cout) + size_t(cb);
            for (int p = 0; p < cp; ++p) {
              const __m512bh wv =
                  reinterpret_cast<__m512bh>(_mm512_loadu_ps(wk + size_t(p) * size_t(cout)));
#pragma GCC unroll 16
              for (int b = 0; b < kPx; ++b)
                acc[b] = _mm512_dpbf16_ps(acc[b],
                                          reinterpret_cast<__m512bh>(_mm512_set1_ps(
                                              in[size_t(b) * size_t(cp) + size_t(p)])),
                                          wv);
            }
          }
#pragma GCC unroll 16
        for (int b = 0; b < kPx; ++b) {
          if (x0 + b >= w) break;
          const __m512 zero = {};
          const __m512 v = a.relu ? (acc[b] > zero ? acc[b] : zero) : acc[b];
          _mm512_storeu_ps(
              a.out + (size_t(y) * size_t(w) + size_t(x0 + b)) * size_t(cout) + size_t(cb), v);
        }
      }
}

// conv_layer in bf16: scratch holds the layer's bf16 weights, then the padded bf16 input.
static void conv_layer_bf16(const ConvLayer& l, const std::vector<float>& in, int w, int h,
                            std::vector<float>& out, bool relu, std::vector<float>& scratch) {
  out.resize(size_t(w) * size_t(h) * size_t(l.cout));
  const int cp = (l.cin + 1) / 2, pw = padded_width_bf16(w);
  const size_t weight_slots = size_t(l.ksize * l.ksize) * size_t(cp) * size_t(l.cout);
  scratch.resize(weight_slots + size_t(pw) * size_t(cp) * size_t(h + 2));
  bf16_weights(l, scratch.data());
  pad_for_conv_bf16(in.data(), w, h, l.cin, scratch.data() + weight_slots);
  ConvArgs a;
  a.in = in.data(), a.weights = nullptr, a.bias = l.bias.data(), a.out = out.data();
  a.width = w, a.height = h, a.cin = l.cin, a.cout = l.cout, a.ksize = l.ksize, a.relu = relu;
  parallel_for(0, size_t(h), 2, [&](size_t r0, size_t r1) {
    conv_rows_bf16(a, scratch.data() + weight_slots, scratch.data(), int(r0), int(r1));
  });
}
#endif
