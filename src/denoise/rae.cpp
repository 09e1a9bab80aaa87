// The `rae` denoiser (rae.h): scripts/denoise/rae.py's function with oneDNN convolutions. The
// per-pixel parts (the network's input, the output's clamp and remodulation) are loops here;
// the U-Net is a chain of oneDNN primitives built once per input size, its five recurrent
// states kept in memories that the chain's last steps overwrite.
#include "denoise/rae.h"

#include <fmt/format.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <vector>

#include "core/parallel.h"
#include "kestrel/error.h"
#include "nn/dnn.h"

namespace kestrel::denoise {

namespace {

using dnnl::memory;
using tag = memory::format_tag;
using dt = memory::data_type;

constexpr char kMagic[9] = "KSTRLRAE";
constexpr uint32_t kArchitecture = 1;
constexpr int kRaeLevels = 5, kRaeInputs = 12, kMultiple = 16;  // 16 = 2^(levels - 1)
constexpr std::array<int, kRaeLevels> kRaeChannels = {32, 48, 64, 80, 96};
constexpr float kSlope = 0.1f;

// The tensors of weights/denoiser_rae.kdw, in order (rae.RAE's named_parameters): enc_a.0-4,
// enc_b.0-4, enc_c.0-4, dec_d.0-3, dec_e.0-3, out.
std::vector<nn::LayerSpec> specs() {
  static const char* kNames[] = {"enc_a.0", "enc_a.1", "enc_a.2", "enc_a.3", "enc_a.4", "enc_b.0",
                                 "enc_b.1", "enc_b.2", "enc_b.3", "enc_b.4", "enc_c.0", "enc_c.1",
                                 "enc_c.2", "enc_c.3", "enc_c.4", "dec_d.0", "dec_d.1", "dec_d.2",
                                 "dec_d.3", "dec_e.0", "dec_e.1", "dec_e.2", "dec_e.3"};
  std::vector<nn::LayerSpec> s;
  for (int l = 0; l < kRaeLevels; ++l)
    s.push_back({kNames[l], kRaeChannels[l], l ? kRaeChannels[l - 1] : kRaeInputs, 3});
  for (int l = 0; l < kRaeLevels; ++l)
    s.push_back({kNames[5 + l], kRaeChannels[l], 2 * kRaeChannels[l], 3});
  for (int l = 0; l < kRaeLevels; ++l)
    s.push_back({kNames[10 + l], kRaeChannels[l], kRaeChannels[l], 3});
  for (int l = 0; l + 1 < kRaeLevels; ++l)
    s.push_back({kNames[15 + l], kRaeChannels[l], kRaeChannels[l + 1] + kRaeChannels[l], 3});
  for (int l = 0; l + 1 < kRaeLevels; ++l)
    s.push_back({kNames[19 + l], kRaeChannels[l], kRaeChannels[l], 3});
  s.push_back({"out", 3, kRaeChannels[0], 3});
  return s;
}
enum : size_t { kEncA = 0, kEncB = 5, kEncC = 10, kDecD = 15, kDecE = 19, kOut = 23 };

// model.demodulation: albedo + 0.01 per channel, 1 where the albedo is (nearly) black.
float demodulation(float albedo, bool black) {
  return black ? 1.0f : std::max(albedo, 0.0f) + kAlbedoEps;
}

}  // namespace

struct Rae::Impl {
  std::vector<nn::ConvLayer> layers;
  size_t parameters = 0;
  nn::Dnn dnn;
  // Built per input size.
  int w = 0, h = 0, Wp = 0, Hp = 0;
  nn::Net net;
  memory input, output;
  std::array<memory, kRaeLevels> state;
  bool fresh = true;  // the states hold no previous frame

  void build(int w_, int h_);
  void clear_states();
};

void Rae::Impl::build(int w_, int h_) {
  w = w_, h = h_;
  Wp = (w + kMultiple - 1) / kMultiple * kMultiple,
  Hp = (h + kMultiple - 1) / kMultiple * kMultiple;
  net = nn::Net{};
  input = memory({{1, kRaeInputs, Hp, Wp}, dt::f32, tag::nchw}, dnn.eng);
  // Zeros in the padding: run() writes only the image.
  std::memset(input.get_data_handle(), 0, input.get_desc().get_size());
  std::array<memory, kRaeLevels> enc;
  memory t = input;
  for (int l = 0; l < kRaeLevels; ++l) {
    const size_t L = size_t(l);
    const memory a = dnn.conv(net, t, layers[kEncA + L], true, false, nullptr, tag::nchw, kSlope);
    state[L] = memory(a.get_desc(), dnn.eng);
    memory e = dnn.conv(net, dnn.concat(net, a, state[L]), layers[kEncB + L], true, false, nullptr,
                        tag::nchw, kSlope);
    enc[L] = dnn.conv(net, e, layers[kEncC + L], true, false, nullptr, tag::nchw, kSlope);
    if (l + 1 < kRaeLevels) t = dnn.pool(net, enc[L]);
  }
  memory u = enc[kRaeLevels - 1];
  for (int l = kRaeLevels - 2; l >= 0; --l) {
    const size_t L = size_t(l);
    u = dnn.conv(net, dnn.up_concat(net, u, enc[L], true), layers[kDecD + L], true, false, nullptr,
                 tag::nchw, kSlope);
    u = dnn.conv(net, u, layers[kDecE + L], true, false, nullptr, tag::nchw, kSlope);
  }
  output = dnn.conv(net, u, layers[kOut], false, true);
  // The recurrent states: each level's output, read by the next frame's concatenation.
  for (size_t L = 0; L < size_t(kRaeLevels); ++L) dnn.copy(net, enc[L], state[L]);
  fresh = true;
}

void Rae::Impl::clear_states() {
  for (memory& s : state)
    if (s) std::memset(s.get_data_handle(), 0, s.get_desc().get_size());
  fresh = false;
}

Rae::Rae(const std::string& weights, bool bf16) : impl_(std::make_unique<Impl>()) {
  impl_->layers = nn::load_layers(weights, kMagic, kArchitecture, specs(), "rae denoiser");
  impl_->dnn.bf16 = bf16 && nn::Dnn::bf16_available();
  for (const nn::ConvLayer& L : impl_->layers)
    impl_->parameters += size_t(L.outputs) * (size_t(L.cin) * size_t(L.ksize * L.ksize) + 1);
}
Rae::~Rae() = default;
Rae::Rae(Rae&&) noexcept = default;
Rae& Rae::operator=(Rae&&) noexcept = default;

size_t Rae::parameters() const {
  return impl_->parameters;
}

bool Rae::bf16() const {
  return impl_->dnn.bf16;
}

void Rae::reset() {
  impl_->fresh = true;
}

void Rae::run(const Planes& in, Planes& out) {
  Impl& m = *impl_;
  const int w = in.width, h = in.height;
  try {
    if (w != m.w || h != m.h) m.build(w, h);
    if (m.fresh) m.clear_states();
  } catch (const dnnl::error& e) {
    throw Error(ErrorCode::unsupported, fmt::format("rae denoiser: oneDNN: {}", e.what()));
  }
  const size_t Wp = size_t(m.Wp), Np = Wp * size_t(m.Hp), W = size_t(w);
  const float *c[3] = {in.ch(0), in.ch(1), in.ch(2)}, *a[3] = {in.ch(3), in.ch(4), in.ch(5)};
  const float* depth = in.ch(9);
  // s: the mean non-sky depth (per-row sums added in row order: the same at any thread count).
  std::vector<double> row_sum(static_cast<size_t>(h));
  std::vector<size_t> row_count(static_cast<size_t>(h));
  parallel_for(0, size_t(h), 8, [&](size_t y0, size_t y1) {
    for (size_t y = y0; y < y1; ++y) {
      double sum = 0;
      size_t count = 0;
      for (size_t p = y * W; p < (y + 1) * W; ++p)
        if (depth[p] > 0) sum += double(depth[p]), ++count;
      row_sum[y] = sum, row_count[y] = count;
    }
  });
  double sum = 0;
  size_t count = 0;
  for (size_t y = 0; y < size_t(h); ++y) sum += row_sum[y], count += row_count[y];
  const float s = count ? float(sum / double(count)) : 1.0f;
  // x = [log(1 + r), albedo, normal, d(z), roughness, black] over the image (the padding stays
  // 0), and per row the largest r.
  std::vector<float> row_max(static_cast<size_t>(h));
  float* x = static_cast<float*>(m.input.get_data_handle());
  parallel_for(0, size_t(h), 8, [&](size_t y0, size_t y1) {
    for (size_t y = y0; y < y1; ++y) {
      float top = 0;
      for (size_t i = 0; i < W; ++i) {
        const size_t p = y * W + i, q = y * Wp + i;
        const bool black = black_albedo(a[0][p], a[1][p], a[2][p]);
        for (size_t k = 0; k < 3; ++k) {
          const float r = std::max(c[k][p], 0.0f) / demodulation(a[k][p], black);
          top = std::max(top, r);
          x[k * Np + q] = std::log1p(r);
          x[(3 + k) * Np + q] = a[k][p];
          x[(6 + k) * Np + q] = in.ch(6 + int(k))[p];
        }
        x[9 * Np + q] = depth[p] > 0 ? depth[p] / (depth[p] + s) : 1.0f;
        x[10 * Np + q] = in.ch(10)[p];
        x[11 * Np + q] = black ? 1.0f : 0.0f;
      }
      row_max[y] = top;
    }
  });
  const float log_top = std::log1p(*std::max_element(row_max.begin(), row_max.end()));
  try {
    m.net.run(m.dnn.strm);
    m.dnn.strm.wait();
  } catch (const dnnl::error& e) {
    throw Error(ErrorCode::unsupported, fmt::format("rae denoiser: oneDNN: {}", e.what()));
  }
  // out = expm1(min(softplus(o), log(1 + max r))) * d (softplus as PyTorch's: o above 20).
  if (out.width != w || out.height != h || out.channels != 3) out = Planes(w, h, 3);
  const float* o = static_cast<const float*>(m.output.get_data_handle());
  parallel_for(0, size_t(h), 8, [&](size_t y0, size_t y1) {
    for (size_t y = y0; y < y1; ++y)
      for (size_t i = 0; i < W; ++i) {
        const size_t p = y * W + i, q = y * Wp + i;
        const bool black = black_albedo(a[0][p], a[1][p], a[2][p]);
        for (size_t k = 0; k < 3; ++k) {
          const float ok = o[k * Np + q];
          const float v = std::min(ok > 20.0f ? ok : std::log1p(std::exp(ok)), log_top);
          out.ch(int(k))[p] = std::expm1(v) * demodulation(a[k][p], black);
        }
      }
  });
}

}  // namespace kestrel::denoise
