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

static void conv_layer(const ConvLayer& l, const std::vector<float>& in, int w, int h,
                       std::vector<float>& out, bool relu, std::vector<float>& scratch) {
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
