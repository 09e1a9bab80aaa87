// `nsrr-rt`, the real-time member of the nsrr family: scripts/upscale/nsrr.py (NSRRRealTime)
// is the reference definition, this computes the same function (tests/upscale compares them
// on a fixture). Align (zero-upsampling, the accumulated backward warp: nsrr_parts.cpp) as
// nsrr does, with N = 2 previous frames and a frame's x = [y, d(z)] as its features; the
// reweighting and reconstruction networks run on cells of 4 x 4 output pixels (the cell's
// pixels folded into channels, pixel_unshuffle / pixel_shuffle order), a quarter of the
// output resolution at either factor, and see the learned TAAU's output (the history) too;
// their output is the logits of the blend of the current frame's bilinear upsampling, the
// history, the current frame's samples around each output pixel and the previous frames' at it
// (nsrr_parts.h: Blend). The warp and grid loops are nsrr_warp.h's, scalar or AVX-512.
#include <fmt/format.h>

#include <algorithm>
#include <cstring>
#include <vector>

#include "core/parallel.h"
#include "core/timer.h"
#include "kestrel/error.h"
#include "upscale/nsrr.h"
#include "upscale/nsrr_parts.h"

namespace kestrel::upscale {

namespace {

using namespace nsrr;
using dnnl::memory;
using tag = memory::format_tag;
using dt = memory::data_type;

constexpr int kPrevious = 2, kCell = 4, kCells = kCell * kCell, kX = 4;
// The grid's channels: the window's x, the history's y (3 per cell pixel), f / 4.
constexpr int kIn = kX * kCells * (kPrevious + 1) + 3 * kCells + 1;
// The blend takes the previous frames' samples at the output pixel only (nsrr.RT_PREVIOUS_RADIUS).
constexpr int kPreviousRadius = 0;
constexpr int kKernel = blend_logits(kPrevious, kPreviousRadius);
// 2: before the bilinear base; 3: a correction of the bilinear base instead of the blend; 6:
// the blend without the history candidate; 8: the previous frames' samples at radius 1 (as
// nsrr's: 9 ms slower per 1280 x 720 output, no better).
constexpr uint32_t kArchitecture = 9;
static_assert(kPrevious + 1 <= kBlendMaxFrames);
static_assert(kIn == GridFill::kChannels && kPrevious + 1 == GridFill::kFrames &&
              kX == GridFill::kX);

// The tensors of weights/upscaler_nsrr_rt.kdw, in order (nsrr.NSRRRealTime's named_parameters).
enum Layer { r1, r2, c1, c2, c3, c4, c5 };
const std::vector<nn::LayerSpec> kSpecs = {{"r1", 16, kIn, 1},
                                           {"r2", kCells* kPrevious, 16, 1},
                                           {"c1", 32, kIn, 1},
                                           {"c2", 24, 32, 3},
                                           {"c3", 24, 24, 3},
                                           {"c4", 24, 48, 1},
                                           {"c5", kKernel* kCells, 24, 1}};

// Output row Y's blend logits, planar (logit c of pixel X at l[c W + X]), from the networks'
// output grid o (cells of 4 x 4 pixels, Gw per row, pixel_shuffle order): a cell's 4 pixels on
// row Y are 4 consecutive channels of each logit's 16.
void cell_logits_row(const float* o, size_t Y, size_t W, size_t Gw, float* l) {
  constexpr size_t K = size_t(kKernel), C = size_t(kCell);
  const float* row = o + (Y / C) * Gw * K * size_t(kCells) + (Y % C) * C;
  const size_t whole = W / C * C;  // the last cell may stick out of the image
  for (size_t X = 0; X < whole; X += C) {
    const float* oc = row + (X / C) * K * size_t(kCells);
    for (size_t c = 0; c < K; ++c) std::memcpy(l + c * W + X, oc + c * kCells, C * sizeof(float));
  }
  if (whole < W) {
    const float* oc = row + (whole / C) * K * size_t(kCells);
    for (size_t c = 0; c < K; ++c)
      std::memcpy(l + c * W + whole, oc + c * kCells, (W - whole) * sizeof(float));
  }
}

class RealTime final : public Member {
 public:
  RealTime(const std::string& weights, int factor, bool bf16);
  void run(const UpscaleInput& in, const FloatImage& history, FloatImage& out,
           Upscaler::Times& times) override;

 private:
  // Built per input size: the output padded to multiples of 8 (two cells, for the pooling),
  // the grid of cells Gw x Gh.
  int w = 0, h = 0, W = 0, H = 0, Gw = 0, Gh = 0;
  Net reweight, reconstruct;
  memory grid_in, reweight_out, out_grid;
  std::vector<int32_t> src;   // N x H x W: the low-res pixel behind W_k at each output pixel, -1
  std::vector<float> packed;  // per window frame and low-res pixel: x = [y, d(z)]

  void build(int w_, int h_);
  // The grid from the window and src (nsrr_warp.h: GridFill).
  void fill_grid(float depth_scale);
  // W_k weighed in the grid by the reweighting network's output.
  template <typename T>
  void weigh(T* g) const;
};

void RealTime::fill_grid(float depth_scale) {
  // Each frame's x = [y, d(z)] packed per low-res pixel (one load per gathered sample).
  const size_t n = size_t(w) * size_t(h), N = size_t(W) * size_t(H);
  packed.resize(window.size() * kX * n);
  parallel_for(0, window.size() * n, 4096, [&](size_t p0, size_t p1) {
    for (size_t p = p0; p < p1; ++p) {
      const Frame& fr = window[p / n];
      const size_t i = p % n;
      float* x = &packed[kX * p];
      for (size_t c = 0; c < 3; ++c) x[c] = fr.y[c * n + i];
      const float z = fr.depth[i];
      x[3] = z > 0 ? z / (z + depth_scale) : 1.0f;
    }
  });
  GridFill a{};
  a.frames = int(std::min(window.size(), size_t(kPrevious) + 1));
  a.at[0] = window[0].sample_at.data();
  for (size_t k = 1; k < size_t(a.frames); ++k) a.at[k] = src.data() + (k - 1) * N;
  a.packed = packed.data(), a.n = n, a.hist = hist.data(), a.W = W, a.H = H, a.Gw = Gw;
  a.last = float(f) / 4.0f;
  a.bf16 = dnn.bf16, a.grid = grid_in.get_data_handle();
  const GridRowsFn rows = grid_rows_for(default_isa());
  parallel_for(0, size_t(Gh), 1, [&](size_t y0, size_t y1) { rows(a, y0, y1); });
}

template <typename T>
void RealTime::weigh(T* g) const {
  // Channel (4 k + c) 16 + sub times w[16 (k - 1) + sub].
  const float* rw = static_cast<const float*>(reweight_out.get_data_handle());
  parallel_for(0, size_t(Gw) * size_t(Gh), 256, [&](size_t p0, size_t p1) {
    for (size_t p = p0; p < p1; ++p) {
      T* gc = g + p * size_t(kIn) + kX * kCells;
      const float* wc = rw + p * size_t(kPrevious * kCells);
      for (size_t k = 0; k < size_t(kPrevious); ++k)
        for (size_t c = 0; c < size_t(kX); ++c)
          for (size_t sub = 0; sub < size_t(kCells); ++sub) {
            T& v = gc[(k * kX + c) * kCells + sub];
            store(v, load(v) * wc[k * kCells + sub]);
          }
    }
  });
}

// The reweighting's first layer widened to 32 outputs (zero weights and bias: ReLU gives 0)
// and its second layer to 32 inputs (zero weights): the same sums, and oneDNN's 1x1 kernel
// for 16 outputs took twice the time of the reconstruction's 32-output layer on the same input.
void widen(nn::ConvLayer& first, nn::ConvLayer& second, int width) {
  const size_t taps = size_t(first.ksize * first.ksize), ci = size_t(first.cin);
  std::vector<float> w(taps * ci * size_t(width), 0.0f);
  for (size_t t = 0; t < taps * ci; ++t)
    for (size_t o = 0; o < size_t(first.outputs); ++o)
      w[t * size_t(width) + o] = first.weights[t * size_t(first.cout) + o];
  first.weights = std::move(w), first.bias.resize(size_t(width), 0.0f);
  first.cout = first.outputs = width;
  const size_t taps2 = size_t(second.ksize * second.ksize), co = size_t(second.cout);
  std::vector<float> w2(taps2 * size_t(width) * co, 0.0f);
  for (size_t t = 0; t < taps2; ++t)
    for (size_t i = 0; i < size_t(second.cin); ++i)
      for (size_t o = 0; o < co; ++o)
        w2[(t * size_t(width) + i) * co + o] =
            second.weights[(t * size_t(second.cin) + i) * co + o];
  second.weights = std::move(w2), second.cin = width;
}

RealTime::RealTime(const std::string& weights, int factor, bool bf16)
    : Member(weights, factor, bf16, kArchitecture, kSpecs, "nsrr-rt upsampler") {
  widen(layers[r1], layers[r2], 32);
}

void RealTime::build(int w_, int h_) {
  w = w_, h = h_, W = f * w, H = f * h;
  Gw = (W + 2 * kCell - 1) / (2 * kCell) * 2, Gh = (H + 2 * kCell - 1) / (2 * kCell) * 2;
  reweight = reconstruct = Net{};
  // Both networks read grid_in: the reweighting first, then (its W_k weighed in place) the
  // reconstruction.
  grid_in = memory({{1, kIn, Gh, Gw}, dnn.act(), tag::nhwc}, dnn.eng);
  memory x = conv(reweight, grid_in, r1, true, false);
  dnnl::post_ops tanh_po;
  tanh_po.append_eltwise(1.0f, dnnl::algorithm::eltwise_tanh, 0.0f, 0.0f);
  tanh_po.append_eltwise(1.0f, dnnl::algorithm::eltwise_linear, 0.5f * kReweightMax,
                         0.5f * kReweightMax);
  reweight_out = conv(reweight, x, r2, false, true, &tanh_po, tag::nhwc);
  memory a = conv(reconstruct, grid_in, c1, true, false);
  a = conv(reconstruct, a, c2, true, false);
  memory b = conv(reconstruct, dnn.pool(reconstruct, a), c3, true, false);
  memory d = conv(reconstruct, dnn.up_concat(reconstruct, b, a), c4, true, false);
  out_grid = conv(reconstruct, d, c5, false, true, nullptr, tag::nhwc);
}

void RealTime::run(const UpscaleInput& in, const FloatImage& history, FloatImage& out,
                   Upscaler::Times& times) {
  Timer timer;
  try {
    if (in.color->width != w || in.color->height != h) {
      window.clear();
      build(in.color->width, in.color->height);
    }
  } catch (const dnnl::error& e) {
    throw Error(ErrorCode::unsupported, fmt::format("nsrr-rt upsampler: oneDNN: {}", e.what()));
  }
  const float s = window.push(in, f, kPrevious);
  window.warp(f, W, H, kPrevious, src);
  history_y(history);
  fill_grid(s);
  times.features = timer.ms();
  Timer net_timer;
  try {
    reweight.run(dnn.strm);
    dnn.strm.wait();
    if (dnn.bf16)
      weigh(static_cast<uint16_t*>(grid_in.get_data_handle()));
    else
      weigh(static_cast<float*>(grid_in.get_data_handle()));
    reconstruct.run(dnn.strm);
    dnn.strm.wait();
  } catch (const dnnl::error& e) {
    throw Error(ErrorCode::unsupported, fmt::format("nsrr-rt upsampler: oneDNN: {}", e.what()));
  }
  times.network = net_timer.ms();
  Timer out_timer;
  const float* o = static_cast<const float*>(out_grid.get_data_handle());
  // The blend of the candidates by the networks' logits (cell (X / 4, Y / 4), pixel_shuffle
  // order).
  base.build(window[0], f, W);
  blend.run(base, hist.data(), window, src, kPrevious, kPreviousRadius, W, H, out,
            [&](size_t Y, float* l) { cell_logits_row(o, Y, size_t(W), size_t(Gw), l); });
  times.reconstruct = out_timer.ms();
}

}  // namespace

std::unique_ptr<NsrrNetwork> make_nsrr_rt(const std::string& weights, int factor, bool bf16) {
  return std::make_unique<RealTime>(weights, factor, bf16);
}

}  // namespace kestrel::upscale
