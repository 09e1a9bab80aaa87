// The `nsrr` upsampler: scripts/upscale/nsrr.py (NSRR) is the reference definition, this
// computes the same function (tests/upscale compares them on a fixture). The data-dependent
// parts (input clean-up, zero-upsampling, the accumulated backward warp, assembling each
// network's input) are loops here and in nsrr_parts.cpp; the three networks (feature
// extraction, reweighting, U-Net) are oneDNN primitives built once per input size, in bf16
// where the CPU has it.
#include <fmt/format.h>

#include <algorithm>
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

constexpr int kPrevious = 3, kFeatures = 12, kExtractIn = 4;
// The U-Net's input: the window's features, f / 4, the history's y.
constexpr int kUnetIn = kFeatures * (kPrevious + 1) + 1 + 3, kReweightIn = 4 * (kPrevious + 1);
constexpr int kKernel = blend_logits(kPrevious);
// 1: before the bilinear base; 4: a correction of the bilinear base instead of the blend; 5:
// the blend without the history candidate.
constexpr uint32_t kArchitecture = 7;
static_assert(kPrevious + 1 <= kBlendMaxFrames);

// The tensors of weights/upscaler_nsrr.kdw, in order (nsrr.NSRR's named_parameters).
enum Layer { e1, e2, e3, r1, r2, r3, u1a, u1b, u2a, u2b, u3a, u3b, u4a, u4b, u5a, u5b };
const std::vector<nn::LayerSpec> kSpecs = {
    {"e1", 32, kExtractIn, 3},  {"e2", 32, 32, 3},   {"e3", 8, 32, 3},
    {"r1", 32, kReweightIn, 3}, {"r2", 32, 32, 3},   {"r3", kPrevious, 32, 3},
    {"u1a", 64, kUnetIn, 3},    {"u1b", 32, 64, 3},  {"u2a", 64, 32, 3},
    {"u2b", 64, 64, 3},         {"u3a", 128, 64, 3}, {"u3b", 128, 128, 3},
    {"u4a", 64, 192, 3},        {"u4b", 64, 64, 3},  {"u5a", 32, 96, 3},
    {"u5b", kKernel, 32, 3}};

class Full final : public Member {
 public:
  Full(const std::string& weights, int factor, bool bf16);
  void run(const UpscaleInput& in, const FloatImage& history, FloatImage& out,
           Upscaler::Times& times) override;

 private:
  // Built per input size.
  int w = 0, h = 0, W = 0, H = 0, Wp = 0, Hp = 0;
  Net extract, reweight, unet;
  memory extract_in, extract_out, reweight_in, reweight_out, unet_in, unet_out;
  std::vector<float> feat;   // (N + 1) x 12 x h x w: the window's features, planar
  std::vector<int32_t> src;  // N x H x W: the low-res pixel behind W_k at each output pixel, -1

  void build(int w_, int h_);
  void frame_features(float s);
};

Full::Full(const std::string& weights, int factor, bool bf16)
    : Member(weights, factor, bf16, kArchitecture, kSpecs, "nsrr upsampler") {}

void Full::build(int w_, int h_) {
  w = w_, h = h_, W = f * w, H = f * h, Wp = (W + 3) / 4 * 4, Hp = (H + 3) / 4 * 4;
  extract = reweight = unet = Net{};
  const dnnl::engine& eng = dnn.eng;
  // Feature extraction: the whole window as one batch.
  extract_in = memory({{kPrevious + 1, kExtractIn, h, w}, dt::f32, tag::nchw}, eng);
  memory x = conv(extract, extract_in, e1, true, false);
  x = conv(extract, x, e2, true, false);
  extract_out = conv(extract, x, e3, true, true);
  // Reweighting: w = 5 (1 + tanh r3(...)).
  reweight_in = memory({{1, kReweightIn, H, W}, dt::f32, tag::nchw}, eng);
  x = conv(reweight, reweight_in, r1, true, false);
  x = conv(reweight, x, r2, true, false);
  dnnl::post_ops tanh_po;
  tanh_po.append_eltwise(1.0f, dnnl::algorithm::eltwise_tanh, 0.0f, 0.0f);
  tanh_po.append_eltwise(1.0f, dnnl::algorithm::eltwise_linear, 0.5f * kReweightMax,
                         0.5f * kReweightMax);
  reweight_out = conv(reweight, x, r3, false, true, &tanh_po);
  // The U-Net.
  unet_in = memory({{1, kUnetIn, Hp, Wp}, dt::f32, tag::nchw}, eng);
  memory a = conv(unet, unet_in, u1a, true, false);
  a = conv(unet, a, u1b, true, false);
  memory b = conv(unet, dnn.pool(unet, a), u2a, true, false);
  b = conv(unet, b, u2b, true, false);
  memory c = conv(unet, dnn.pool(unet, b), u3a, true, false);
  c = conv(unet, c, u3b, true, false);
  memory d = conv(unet, dnn.up_concat(unet, c, b), u4a, true, false);
  d = conv(unet, d, u4b, true, false);
  memory o = conv(unet, dnn.up_concat(unet, d, a), u5a, true, false);
  unet_out = conv(unet, o, u5b, false, true);
  feat.assign(size_t(kPrevious + 1) * kFeatures * size_t(w) * size_t(h), 0.0f);
}

// x = [y, d(z)] of every frame of the window (zeros for the missing ones), the extraction
// network, and the 12 features of each frame in `feat`.
void Full::frame_features(float s) {
  const size_t n = size_t(w) * size_t(h);
  float* x = static_cast<float*>(extract_in.get_data_handle());
  std::fill(x, x + (kPrevious + 1) * kExtractIn * n, 0.0f);
  for (size_t k = 0; k < window.size(); ++k) {
    const Frame& fr = window[k];
    float* xk = x + k * kExtractIn * n;
    for (size_t p = 0; p < n; ++p) {
      for (size_t c = 0; c < 3; ++c) xk[c * n + p] = fr.y[c * n + p];
      const float z = fr.depth[p];
      xk[3 * n + p] = z > 0 ? z / (z + s) : 1.0f;
    }
  }
  extract.run(dnn.strm);
  dnn.strm.wait();
  const float* e = static_cast<const float*>(extract_out.get_data_handle());
  for (size_t k = 0; k < size_t(kPrevious + 1); ++k) {
    float* fk = &feat[k * kFeatures * n];
    std::copy(x + k * kExtractIn * n, x + (k + 1) * kExtractIn * n, fk);
    std::copy(e + k * 8 * n, e + (k + 1) * 8 * n, fk + kExtractIn * n);
  }
}

void Full::run(const UpscaleInput& in, const FloatImage& history, FloatImage& out,
               Upscaler::Times& times) {
  Timer timer;
  try {
    if (in.color->width != w || in.color->height != h) {
      window.clear();
      build(in.color->width, in.color->height);
    }
  } catch (const dnnl::error& e) {
    throw Error(ErrorCode::unsupported, fmt::format("nsrr upsampler: oneDNN: {}", e.what()));
  }
  const size_t n = size_t(w) * size_t(h), N = size_t(W) * size_t(H);
  const float s = window.push(in, f, kPrevious);
  try {
    frame_features(s);
    window.warp(f, W, H, kPrevious, src);
    history_y(history);
    // The reweighting network's input: [Z_0[:4], W_1[:4], ..., W_N[:4]].
    const std::vector<int32_t>& cur = window[0].sample_at;
    float* ri = static_cast<float*>(reweight_in.get_data_handle());
    parallel_for(0, N, 4096, [&](size_t b, size_t e) {
      for (size_t q = b; q < e; ++q) {
        const int32_t i0 = cur[q];
        for (size_t c = 0; c < 4; ++c) ri[c * N + q] = i0 >= 0 ? feat[c * n + size_t(i0)] : 0.0f;
        for (size_t k = 1; k <= size_t(kPrevious); ++k) {
          const int32_t ik = src[(k - 1) * N + q];
          const float* fk = &feat[k * kFeatures * n];
          for (size_t c = 0; c < 4; ++c)
            ri[(4 * k + c) * N + q] = ik >= 0 ? fk[c * n + size_t(ik)] : 0.0f;
        }
      }
    });
    times.features = timer.ms();
    Timer net_timer;
    reweight.run(dnn.strm);
    dnn.strm.wait();
    // The U-Net's input: [Z_0, w_1 W_1, ..., w_N W_N, f / 4, Hy], zero padding to Wp x Hp.
    const float* rw = static_cast<const float*>(reweight_out.get_data_handle());
    float* ui = static_cast<float*>(unet_in.get_data_handle());
    const size_t Np = size_t(Wp) * size_t(Hp);
    parallel_for(0, size_t(Hp), 4, [&](size_t r0, size_t r1) {
      for (size_t Y = r0; Y < r1; ++Y)
        for (size_t X = 0; X < size_t(Wp); ++X) {
          const size_t qp = Y * size_t(Wp) + X;
          const bool inside = X < size_t(W) && Y < size_t(H);
          const size_t q = Y * size_t(W) + X;
          const int32_t i0 = inside ? cur[q] : -1;
          for (size_t c = 0; c < size_t(kFeatures); ++c)
            ui[c * Np + qp] = i0 >= 0 ? feat[c * n + size_t(i0)] : 0.0f;
          for (size_t k = 1; k <= size_t(kPrevious); ++k) {
            const int32_t ik = inside ? src[(k - 1) * N + q] : -1;
            const float wk = inside ? rw[(k - 1) * N + q] : 0.0f;
            const float* fk = &feat[k * kFeatures * n];
            for (size_t c = 0; c < size_t(kFeatures); ++c)
              ui[(k * kFeatures + c) * Np + qp] = ik >= 0 ? wk * fk[c * n + size_t(ik)] : 0.0f;
          }
          ui[size_t(kUnetIn - 4) * Np + qp] = inside ? float(f) / 4.0f : 0.0f;
          for (size_t c = 0; c < 3; ++c)
            ui[(size_t(kUnetIn - 3) + c) * Np + qp] = inside ? hist[c * N + q] : 0.0f;
        }
    });
    unet.run(dnn.strm);
    dnn.strm.wait();
    times.network = net_timer.ms();
  } catch (const dnnl::error& e) {
    throw Error(ErrorCode::unsupported, fmt::format("nsrr upsampler: oneDNN: {}", e.what()));
  }
  Timer out_timer;
  const float* uo = static_cast<const float*>(unet_out.get_data_handle());
  const size_t Np = size_t(Wp) * size_t(Hp);
  // The blend of the candidates by the U-Net's logits (its output padded to Wp x Hp).
  base.build(window[0], f, W);
  blend.run(base, hist.data(), window, src, kPrevious, kBlendRadius, W, H, out,
            [&](size_t Y, float* l) {
              for (size_t c = 0; c < size_t(kKernel); ++c)
                std::copy_n(uo + c * Np + Y * size_t(Wp), size_t(W), l + c * size_t(W));
            });
  times.reconstruct = out_timer.ms();
}

}  // namespace

std::unique_ptr<NsrrNetwork> make_nsrr(const std::string& weights, int factor, bool bf16) {
  return std::make_unique<Full>(weights, factor, bf16);
}

}  // namespace kestrel::upscale
