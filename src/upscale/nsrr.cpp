// The `nsrr` upsampler: scripts/upscale/nsrr.py is the reference definition, this computes the
// same function (tests/upscale compares them on a fixture). The data-dependent parts (input
// clean-up, zero-upsampling, the accumulated backward warp, assembling each network's input)
// are loops here; the three networks (feature extraction, reweighting, U-Net) are oneDNN
// primitives built once per input size, in bf16 where the CPU has it.
#include "upscale/nsrr.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <deque>
#include <oneapi/dnnl/dnnl.hpp>
#include <unordered_map>
#include <vector>

#include "core/parallel.h"
#include "core/timer.h"
#include "kestrel/error.h"
#include "nn/weights.h"

namespace kestrel::upscale {

namespace {

constexpr float kLuma[3] = {0.2126f, 0.7152f, 0.0722f};
constexpr float kMaxMotion = 65536.0f, kReweightMax = 10.0f, kYMax = 0.999f;
constexpr int kPrevious = 3, kFeatures = 12, kExtractIn = 4;
constexpr int kUnetIn = kFeatures * (kPrevious + 1) + 1, kReweightIn = 4 * (kPrevious + 1);
constexpr char kMagic[9] = "KSTRLNSR";
constexpr uint32_t kArchitecture = 1;

float luma(const float* c) {
  return kLuma[0] * c[0] + kLuma[1] * c[1] + kLuma[2] * c[2];
}
float finite_or_zero(float v) {
  return std::isfinite(v) ? v : 0.0f;
}
int clampi(int v, int lo, int hi) {
  return v < lo ? lo : (v > hi ? hi : v);
}
int floor_int(float x) {  // |x| < 2^31
  const int i = int(x);
  return i - (float(i) > x);
}

// The tensors of weights/upscaler_nsrr.kdw, in order (nsrr.NSRR's named_parameters).
enum Layer { e1, e2, e3, r1, r2, r3, u1a, u1b, u2a, u2b, u3a, u3b, u4a, u4b, u5a, u5b };
const std::vector<nn::LayerSpec> kSpecs = {
    {"e1", 32, kExtractIn, 3},  {"e2", 32, 32, 3},   {"e3", 8, 32, 3},
    {"r1", 32, kReweightIn, 3}, {"r2", 32, 32, 3},   {"r3", kPrevious, 32, 3},
    {"u1a", 64, kUnetIn, 3},    {"u1b", 32, 64, 3},  {"u2a", 64, 32, 3},
    {"u2b", 64, 64, 3},         {"u3a", 128, 64, 3}, {"u3b", 128, 128, 3},
    {"u4a", 64, 192, 3},        {"u4b", 64, 64, 3},  {"u5a", 32, 96, 3},
    {"u5b", 3, 32, 3}};

using dnnl::memory;
using tag = memory::format_tag;
using dt = memory::data_type;

// A chain of oneDNN primitives and the memories they read and write.
struct Net {
  struct Step {
    dnnl::primitive p;
    std::unordered_map<int, memory> args;
  };
  std::vector<Step> steps;
  void run(dnnl::stream& s) {
    for (Step& st : steps) st.p.execute(s, st.args);
  }
};

// One low-resolution frame of the window, cleaned as nsrr.clean does.
struct Frame {
  int w = 0, h = 0;
  float jx = 0.5f, jy = 0.5f;
  std::vector<float> y, depth, motion;  // planar: 3, 1, 2 channels
  std::vector<int32_t> sample_at;  // output pixel -> the low-res pixel whose sample it holds, -1
};

}  // namespace

struct Nsrr::Impl {
  int f = 2;
  bool use_bf16 = false;
  size_t parameters = 0;
  std::vector<nn::ConvLayer> layers;
  dnnl::engine eng{dnnl::engine::kind::cpu, 0};
  dnnl::stream strm{eng};
  // Built per input size.
  int w = 0, h = 0, W = 0, H = 0, Wp = 0, Hp = 0;
  Net extract, reweight, unet;
  memory extract_in, extract_out, reweight_in, reweight_out, unet_in, unet_out;
  std::deque<Frame> window;  // [current, previous, ...]
  std::vector<float> feat;   // (N + 1) x 12 x h x w: the window's features, planar
  std::vector<int32_t> src;  // N x H x W: the low-res pixel behind W_k at each output pixel, -1

  dt act() const { return use_bf16 ? dt::bf16 : dt::f32; }
  memory weights_of(const nn::ConvLayer& L, const memory::desc& want);
  memory conv(Net& net, memory in, Layer id, bool relu, bool last, int batch, int hh, int ww,
              const dnnl::post_ops* extra = nullptr);
  void build(int w_, int h_);
  void frame_features(float s);
  void warp();
};

memory Nsrr::Impl::weights_of(const nn::ConvLayer& L, const memory::desc& want) {
  // ConvLayer: [ky][kx][cin][cout stride] -> oihw.
  const int co = L.outputs, ci = L.cin;
  memory plain({{co, ci, 3, 3}, dt::f32, tag::oihw}, eng);
  float* p = static_cast<float*>(plain.get_data_handle());
  for (int o = 0; o < co; ++o)
    for (int i = 0; i < ci; ++i)
      for (int t = 0; t < 9; ++t)
        p[(size_t(o) * size_t(ci) + size_t(i)) * 9 + size_t(t)] =
            L.weights[(size_t(t) * size_t(ci) + size_t(i)) * size_t(L.cout) + size_t(o)];
  memory out(want, eng);
  dnnl::reorder(plain, out).execute(strm, plain, out);
  return out;
}

memory Nsrr::Impl::conv(Net& net, memory in, Layer id, bool relu, bool last, int batch, int hh,
                        int ww, const dnnl::post_ops* extra) {
  const nn::ConvLayer& L = layers[size_t(id)];
  const memory::desc src_any({batch, L.cin, hh, ww}, act(), tag::any);
  const memory::desc dst_any({batch, L.outputs, hh, ww}, last ? dt::f32 : act(),
                             last ? tag::nchw : tag::any);
  const memory::desc wei_any({L.outputs, L.cin, 3, 3}, act(), tag::any);
  const memory::desc bias_md({L.outputs}, dt::f32, tag::x);
  dnnl::convolution_forward::desc cd(dnnl::prop_kind::forward_inference,
                                     dnnl::algorithm::convolution_direct, src_any, wei_any, bias_md,
                                     dst_any, {1, 1}, {1, 1}, {1, 1});
  dnnl::post_ops po = extra ? *extra : dnnl::post_ops();
  if (relu) po.append_eltwise(1.0f, dnnl::algorithm::eltwise_relu, 0.0f, 0.0f);
  dnnl::primitive_attr attr;
  attr.set_post_ops(po);
  dnnl::convolution_forward::primitive_desc pd(cd, attr, eng);
  if (pd.src_desc() != in.get_desc()) {
    memory r(pd.src_desc(), eng);
    net.steps.push_back({dnnl::reorder(in, r), {{DNNL_ARG_FROM, in}, {DNNL_ARG_TO, r}}});
    in = r;
  }
  memory bias(bias_md, eng);
  std::copy(L.bias.begin(), L.bias.begin() + L.outputs,
            static_cast<float*>(bias.get_data_handle()));
  memory dst(pd.dst_desc(), eng);
  net.steps.push_back({dnnl::convolution_forward(pd),
                       {{DNNL_ARG_SRC, in},
                        {DNNL_ARG_WEIGHTS, weights_of(L, pd.weights_desc())},
                        {DNNL_ARG_BIAS, bias},
                        {DNNL_ARG_DST, dst}}});
  return dst;
}

void Nsrr::Impl::build(int w_, int h_) {
  w = w_, h = h_, W = f * w, H = f * h, Wp = (W + 3) / 4 * 4, Hp = (H + 3) / 4 * 4;
  extract = reweight = unet = Net{};
  // Feature extraction: the whole window as one batch.
  extract_in = memory({{kPrevious + 1, kExtractIn, h, w}, dt::f32, tag::nchw}, eng);
  memory x = conv(extract, extract_in, e1, true, false, kPrevious + 1, h, w);
  x = conv(extract, x, e2, true, false, kPrevious + 1, h, w);
  extract_out = conv(extract, x, e3, true, true, kPrevious + 1, h, w);
  // Reweighting: w = 5 (1 + tanh r3(...)).
  reweight_in = memory({{1, kReweightIn, H, W}, dt::f32, tag::nchw}, eng);
  x = conv(reweight, reweight_in, r1, true, false, 1, H, W);
  x = conv(reweight, x, r2, true, false, 1, H, W);
  dnnl::post_ops tanh_po;
  tanh_po.append_eltwise(1.0f, dnnl::algorithm::eltwise_tanh, 0.0f, 0.0f);
  tanh_po.append_eltwise(1.0f, dnnl::algorithm::eltwise_linear, 0.5f * kReweightMax,
                         0.5f * kReweightMax);
  reweight_out = conv(reweight, x, r3, false, true, 1, H, W, &tanh_po);
  // The U-Net.
  unet_in = memory({{1, kUnetIn, Hp, Wp}, dt::f32, tag::nchw}, eng);
  auto pool = [&](memory in, int hh, int ww) {
    const memory::desc d = in.get_desc();
    const memory::desc out_any({1, d.dims()[1], hh / 2, ww / 2}, act(), tag::any);
    dnnl::pooling_forward::primitive_desc pd({dnnl::prop_kind::forward_inference,
                                              dnnl::algorithm::pooling_max,
                                              d,
                                              out_any,
                                              {2, 2},
                                              {2, 2},
                                              {0, 0},
                                              {0, 0}},
                                             eng);
    memory out(pd.dst_desc(), eng);
    unet.steps.push_back({dnnl::pooling_forward(pd), {{DNNL_ARG_SRC, in}, {DNNL_ARG_DST, out}}});
    return out;
  };
  auto up_concat = [&](memory low, memory skip, int hh, int ww) {
    const memory::desc d = low.get_desc();
    const memory::desc up_md({1, d.dims()[1], hh, ww}, act(), tag::any);
    dnnl::resampling_forward::primitive_desc pd(
        {dnnl::prop_kind::forward_inference, dnnl::algorithm::resampling_linear, d, up_md}, eng);
    memory up(pd.dst_desc(), eng);
    unet.steps.push_back({dnnl::resampling_forward(pd), {{DNNL_ARG_SRC, low}, {DNNL_ARG_DST, up}}});
    dnnl::concat::primitive_desc cpd(1, {up.get_desc(), skip.get_desc()}, eng);
    memory cat(cpd.dst_desc(), eng);
    unet.steps.push_back(
        {dnnl::concat(cpd),
         {{DNNL_ARG_MULTIPLE_SRC, up}, {DNNL_ARG_MULTIPLE_SRC + 1, skip}, {DNNL_ARG_DST, cat}}});
    return cat;
  };
  memory a = conv(unet, unet_in, u1a, true, false, 1, Hp, Wp);
  a = conv(unet, a, u1b, true, false, 1, Hp, Wp);
  memory b = conv(unet, pool(a, Hp, Wp), u2a, true, false, 1, Hp / 2, Wp / 2);
  b = conv(unet, b, u2b, true, false, 1, Hp / 2, Wp / 2);
  memory c = conv(unet, pool(b, Hp / 2, Wp / 2), u3a, true, false, 1, Hp / 4, Wp / 4);
  c = conv(unet, c, u3b, true, false, 1, Hp / 4, Wp / 4);
  memory d = conv(unet, up_concat(c, b, Hp / 2, Wp / 2), u4a, true, false, 1, Hp / 2, Wp / 2);
  d = conv(unet, d, u4b, true, false, 1, Hp / 2, Wp / 2);
  memory o = conv(unet, up_concat(d, a, Hp, Wp), u5a, true, false, 1, Hp, Wp);
  unet_out = conv(unet, o, u5b, false, true, 1, Hp, Wp);
  feat.assign(size_t(kPrevious + 1) * kFeatures * size_t(w) * size_t(h), 0.0f);
  src.assign(size_t(kPrevious) * size_t(W) * size_t(H), -1);
}

// x = [y, d(z)] of every frame of the window (zeros for the missing ones), the extraction
// network, and the 12 features of each frame in `feat`.
void Nsrr::Impl::frame_features(float s) {
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
  extract.run(strm);
  strm.wait();
  const float* e = static_cast<const float*>(extract_out.get_data_handle());
  for (size_t k = 0; k < size_t(kPrevious + 1); ++k) {
    float* fk = &feat[k * kFeatures * n];
    std::copy(x + k * kExtractIn * n, x + (k + 1) * kExtractIn * n, fk);
    std::copy(e + k * 8 * n, e + (k + 1) * 8 * n, fk + kExtractIn * n);
  }
}

// The accumulated backward warp (nsrr.warp_positions + gather_nearest) as source indices.
void Nsrr::Impl::warp() {
  const size_t n = size_t(w) * size_t(h);
  const float ff = float(f);
  parallel_for(0, size_t(H), 4, [&](size_t r0, size_t r1) {
    for (size_t Y = r0; Y < r1; ++Y)
      for (size_t X = 0; X < size_t(W); ++X) {
        float px = float(X) + 0.5f, py = float(Y) + 0.5f;
        for (size_t k = 1; k <= size_t(kPrevious); ++k) {
          int32_t& out = src[((k - 1) * size_t(H) + Y) * size_t(W) + X];
          out = -1;
          if (k >= window.size()) continue;
          const float* m = window[k - 1].motion.data();
          // bilinear_at(m, px / f, py / f): edges clamped, pixel centres at i + 0.5.
          const float xf = px / ff - 0.5f, yf = py / ff - 0.5f;
          const int x0 = floor_int(xf), y0 = floor_int(yf);
          const float tx = xf - float(x0), ty = yf - float(y0);
          const size_t ix[2] = {size_t(clampi(x0, 0, w - 1)), size_t(clampi(x0 + 1, 0, w - 1))};
          const size_t iy[2] = {size_t(clampi(y0, 0, h - 1)), size_t(clampi(y0 + 1, 0, h - 1))};
          float mv[2];
          for (size_t c = 0; c < 2; ++c) {
            const float* mc = m + c * n;
            const float top = (1 - ty) * (1 - tx) * mc[iy[0] * size_t(w) + ix[0]] +
                              (1 - ty) * tx * mc[iy[0] * size_t(w) + ix[1]];
            mv[c] = top + ty * (1 - tx) * mc[iy[1] * size_t(w) + ix[0]] +
                    ty * tx * mc[iy[1] * size_t(w) + ix[1]];
          }
          px = px + ff * mv[0], py = py + ff * mv[1];
          if (px >= 0 && px < float(W) && py >= 0 && py < float(H))
            out = window[k].sample_at[size_t(floor_int(py)) * size_t(W) + size_t(floor_int(px))];
        }
      }
  });
}

Nsrr::Nsrr(const std::string& weights, int factor, bool bf16) : impl_(std::make_unique<Impl>()) {
  Impl& m = *impl_;
  m.f = factor;
  m.layers = nn::load_layers(weights, kMagic, kArchitecture, kSpecs, "nsrr upsampler");
  for (const nn::ConvLayer& L : m.layers)
    m.parameters += size_t(L.outputs) * (size_t(L.cin) * 9 + 1);
  m.use_bf16 = bf16 && dnnl::get_effective_cpu_isa() >= dnnl::cpu_isa::avx512_core_bf16;
}
Nsrr::~Nsrr() = default;
Nsrr::Nsrr(Nsrr&&) noexcept = default;
Nsrr& Nsrr::operator=(Nsrr&&) noexcept = default;

void Nsrr::reset() {
  impl_->window.clear();
}
size_t Nsrr::parameters() const {
  return impl_->parameters;
}
bool Nsrr::bf16() const {
  return impl_->use_bf16;
}

void Nsrr::run(const UpscaleInput& in, FloatImage& out, Upscaler::Times& times) {
  Impl& m = *impl_;
  const int w = in.color->width, h = in.color->height, f = m.f;
  Timer timer;
  try {
    if (w != m.w || h != m.h) {
      m.window.clear();
      m.build(w, h);
    }
  } catch (const dnnl::error& e) {
    throw Error(ErrorCode::unsupported, fmt::format("nsrr upsampler: oneDNN: {}", e.what()));
  }
  const int W = m.W, H = m.H;
  const size_t n = size_t(w) * size_t(h), N = size_t(W) * size_t(H);
  // The current frame, cleaned (nsrr.clean), and where its samples land (zero_upsample).
  Frame fr = m.window.size() > size_t(kPrevious) ? std::move(m.window.back()) : Frame{};
  if (m.window.size() > size_t(kPrevious)) m.window.pop_back();
  fr.w = w, fr.h = h, fr.jx = in.jitter_x, fr.jy = in.jitter_y;
  fr.y.resize(3 * n), fr.depth.resize(n), fr.motion.resize(2 * n), fr.sample_at.assign(N, -1);
  const int mc = in.motion ? in.motion->channels : 0;
  double depth_sum = 0;
  size_t depth_count = 0;
  for (size_t p = 0; p < n; ++p) {
    float c[3];
    for (size_t k = 0; k < 3; ++k)
      c[k] = std::max(finite_or_zero(in.color->pixels[3 * p + k]), 0.0f);
    const float s = 1.0f / (1.0f + luma(c));
    for (size_t k = 0; k < 3; ++k) fr.y[k * n + p] = c[k] * s;
    const float z = in.depth ? std::max(finite_or_zero(in.depth->pixels[p]), 0.0f) : 1.0f;
    fr.depth[p] = z;
    if (z > 0) depth_sum += double(z), ++depth_count;
    for (size_t k = 0; k < 2; ++k)
      fr.motion[k * n + p] = mc ? std::clamp(finite_or_zero(in.motion->pixels[size_t(mc) * p + k]),
                                             -kMaxMotion, kMaxMotion)
                                : 0.0f;
  }
  for (int j = 0; j < h; ++j)
    for (int i = 0; i < w; ++i) {
      const int X = clampi(floor_int(float(f) * (float(i) + fr.jx)), 0, W - 1);
      const int Y = clampi(floor_int(float(f) * (float(j) + fr.jy)), 0, H - 1);
      fr.sample_at[size_t(Y) * size_t(W) + size_t(X)] = j * w + i;
    }
  m.window.push_front(std::move(fr));
  const float s = depth_count ? float(depth_sum / double(depth_count)) : 1.0f;
  try {
    m.frame_features(s);
    m.warp();
    // The reweighting network's input: [Z_0[:4], W_1[:4], ..., W_N[:4]].
    const std::vector<float>& feat = m.feat;
    const std::vector<int32_t>& cur = m.window.front().sample_at;
    float* ri = static_cast<float*>(m.reweight_in.get_data_handle());
    parallel_for(0, N, 4096, [&](size_t b, size_t e) {
      for (size_t q = b; q < e; ++q) {
        const int32_t i0 = cur[q];
        for (size_t c = 0; c < 4; ++c) ri[c * N + q] = i0 >= 0 ? feat[c * n + size_t(i0)] : 0.0f;
        for (size_t k = 1; k <= size_t(kPrevious); ++k) {
          const int32_t ik = m.src[(k - 1) * N + q];
          const float* fk = &feat[k * kFeatures * n];
          for (size_t c = 0; c < 4; ++c)
            ri[(4 * k + c) * N + q] = ik >= 0 ? fk[c * n + size_t(ik)] : 0.0f;
        }
      }
    });
    times.features = timer.ms();
    Timer net_timer;
    m.reweight.run(m.strm);
    m.strm.wait();
    // The U-Net's input: [Z_0, w_1 W_1, ..., w_N W_N, f / 4], zero padding to Wp x Hp.
    const float* rw = static_cast<const float*>(m.reweight_out.get_data_handle());
    float* ui = static_cast<float*>(m.unet_in.get_data_handle());
    const size_t Np = size_t(m.Wp) * size_t(m.Hp);
    parallel_for(0, size_t(m.Hp), 4, [&](size_t r0, size_t r1) {
      for (size_t Y = r0; Y < r1; ++Y)
        for (size_t X = 0; X < size_t(m.Wp); ++X) {
          const size_t qp = Y * size_t(m.Wp) + X;
          const bool inside = X < size_t(W) && Y < size_t(H);
          const size_t q = Y * size_t(W) + X;
          const int32_t i0 = inside ? cur[q] : -1;
          for (size_t c = 0; c < size_t(kFeatures); ++c)
            ui[c * Np + qp] = i0 >= 0 ? feat[c * n + size_t(i0)] : 0.0f;
          for (size_t k = 1; k <= size_t(kPrevious); ++k) {
            const int32_t ik = inside ? m.src[(k - 1) * N + q] : -1;
            const float wk = inside ? rw[(k - 1) * N + q] : 0.0f;
            const float* fk = &feat[k * kFeatures * n];
            for (size_t c = 0; c < size_t(kFeatures); ++c)
              ui[(k * kFeatures + c) * Np + qp] = ik >= 0 ? wk * fk[c * n + size_t(ik)] : 0.0f;
          }
          ui[size_t(kUnetIn - 1) * Np + qp] = inside ? float(f) / 4.0f : 0.0f;
        }
    });
    m.unet.run(m.strm);
    m.strm.wait();
    times.network = net_timer.ms();
  } catch (const dnnl::error& e) {
    throw Error(ErrorCode::unsupported, fmt::format("nsrr upsampler: oneDNN: {}", e.what()));
  }
  Timer out_timer;
  out.width = W, out.height = H, out.channels = 3;
  out.pixels.resize(3 * N);
  const float* uo = static_cast<const float*>(m.unet_out.get_data_handle());
  const size_t Np = size_t(m.Wp) * size_t(m.Hp);
  parallel_for(0, size_t(H), 8, [&](size_t r0, size_t r1) {
    for (size_t Y = r0; Y < r1; ++Y)
      for (size_t X = 0; X < size_t(W); ++X) {
        const size_t qp = Y * size_t(m.Wp) + X;
        float y[3];
        for (size_t c = 0; c < 3; ++c) y[c] = std::clamp(uo[c * Np + qp], 0.0f, kYMax);
        const float d = std::max(1.0f - luma(y), 1e-3f);
        for (size_t c = 0; c < 3; ++c) out.pixels[3 * (Y * size_t(W) + X) + c] = y[c] / d;
      }
  });
  times.reconstruct = out_timer.ms();
}

}  // namespace kestrel::upscale
