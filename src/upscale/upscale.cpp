// kestrel's temporal upsampler: scripts/upscale/model.py is the reference definition; this
// computes the same function (tests/upscale compares them on a fixture). Layout: colours
// channels-last; the network's grid is 1/4 of the output in each dimension.
#include "kestrel/upscale.h"

#include <fmt/format.h>
#include <xmmintrin.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdlib>
#include <vector>

#include "core/parallel.h"
#include "core/timer.h"
#include "kestrel/error.h"
#include "nn/conv.h"
#include "nn/weights.h"
#include "upscale/nsrr.h"
#include "upscale/reconstruct.h"

namespace kestrel {

using upscale::Axis;
using upscale::GridAxis;
using upscale::HistoryArgs;
using upscale::LowRes;
using upscale::Recon;

namespace {

constexpr float kLuma[3] = {0.2126f, 0.7152f, 0.0722f};
constexpr int kFeatures = 11, kLowFeatures = 8, kOutputs = 3;
constexpr float kCurrentSharpness = 2.0f;
constexpr char kMagic[9] = "KSTRLUPW";
constexpr uint32_t kArchitecture = 1;
// The TAAU-like baseline's constants, picked on the training clips by a grid search
// (scripts/upscale/train.py --tune-taau; weights/upscaler.json records them).
constexpr float kTaauA = 0.6f, kTaauGamma = 0.75f, kTaauKappa = 0.0625f;

struct FlushDenormals {
  unsigned saved = _mm_getcsr();
  FlushDenormals() { _mm_setcsr(saved | 0x8040); }
  ~FlushDenormals() { _mm_setcsr(saved); }
};

template <class F>
void parallel_rows(int h, int grain, F&& f) {
  parallel_for(0, size_t(h), size_t(grain), [&](size_t begin, size_t end) {
    FlushDenormals ftz;
    f(int(begin), int(end));
  });
}

#include "upscale/sampling.inl"

void check_input(const UpscaleInput& in) {
  if (!in.color) throw Error(ErrorCode::invalid_argument, "upscale: the colour image is required");
  const FloatImage& c = *in.color;
  if (c.channels != 3 || c.width <= 0 || c.height <= 0 ||
      c.pixels.size() != size_t(c.width) * size_t(c.height) * 3)
    throw Error(ErrorCode::invalid_argument,
                fmt::format("upscale: colour must be a non-empty 3-channel image (got {}x{}x{})",
                            c.width, c.height, c.channels));
  auto same = [&](const FloatImage* im, const char* name, int c0, int c1) {
    if (!im) return;
    if (im->width != c.width || im->height != c.height)
      throw Error(ErrorCode::invalid_argument,
                  fmt::format("upscale: {} is {}x{}, colour is {}x{}", name, im->width, im->height,
                              c.width, c.height));
    if (im->channels < c0 || im->channels > c1 ||
        im->pixels.size() != size_t(im->width) * size_t(im->height) * size_t(im->channels))
      throw Error(ErrorCode::invalid_argument,
                  fmt::format("upscale: {} has {} channels (expected {}{})", name, im->channels, c0,
                              c1 > c0 ? fmt::format(" to {}", c1) : ""));
  };
  same(in.depth, "depth", 1, 1);
  same(in.motion, "motion", 2, 3);
  if (!std::isfinite(in.jitter_x) || !std::isfinite(in.jitter_y) || in.jitter_x < -1 ||
      in.jitter_x > 2 || in.jitter_y < -1 || in.jitter_y > 2)
    throw Error(ErrorCode::invalid_argument,
                fmt::format("upscale: jitter ({}, {}) is not a sub-pixel position", in.jitter_x,
                            in.jitter_y));
}

}  // namespace

namespace upscale {
const UpscaleKernels& upscale_kernels(Isa isa) {
  require_supported(isa);
  switch (isa) {
    case Isa::avx512:
      return upscale_kernels_avx512();
    case Isa::avx2:
      return upscale_kernels_avx2();
    default:
      return upscale_kernels_sse2();
  }
}

void Axis::build(int out, int in, int f, float jitter, float sharpness) {
  i0.resize(size_t(out)), d0.resize(size_t(out));
  for (auto& wk : w) wk.resize(size_t(out));
  for (int X = 0; X < out; ++X) {
    const float u = (float(X) + 0.5f) / float(f) - jitter;
    const int i = clampi(floor_int(u + 0.5f), 0, in - 1);
    i0[size_t(X)] = i;
    d0[size_t(X)] = u - float(i);
    for (int k = 0; k < 3; ++k) {
      const float d = u - float(i + k - 1);
      w[k][size_t(X)] = std::exp(-sharpness * d * d);
    }
  }
}

void GridAxis::build(int out, int grid) {
  a.resize(size_t(out)), b.resize(size_t(out)), t.resize(size_t(out));
  for (int X = 0; X < out; ++X) {
    const float xf = (float(X) + 0.5f) / 4.0f - 0.5f;
    const int x0 = floor_int(xf);
    a[size_t(X)] = clampi(x0, 0, grid - 1), b[size_t(X)] = clampi(x0 + 1, 0, grid - 1);
    t[size_t(X)] = xf - float(x0);
  }
}

}  // namespace upscale

const char* upscale_method_name(UpscaleMethod m) {
  switch (m) {
    case UpscaleMethod::neural:
      return "neural";
    case UpscaleMethod::taau:
      return "taau";
    case UpscaleMethod::bicubic:
      return "bicubic";
    case UpscaleMethod::bilinear:
      return "bilinear";
    case UpscaleMethod::nsrr:
      return "nsrr";
    case UpscaleMethod::nsrr_rt:
      return "nsrr-rt";
  }
  return "?";
}

namespace {
constexpr UpscaleMethod kAllMethods[] = {UpscaleMethod::neural,  UpscaleMethod::taau,
                                         UpscaleMethod::bicubic, UpscaleMethod::bilinear,
                                         UpscaleMethod::nsrr,    UpscaleMethod::nsrr_rt};
}  // namespace

std::optional<UpscaleMethod> upscale_method_from_name(std::string_view name) {
  for (UpscaleMethod m : kAllMethods)
    if (name == upscale_method_name(m)) return m;
  return std::nullopt;
}

std::string upscale_method_list(const char* sep) {
  std::string out;
  for (UpscaleMethod m : kAllMethods)
    out += (out.empty() ? "" : sep) + std::string(upscale_method_name(m));
  return out;
}

std::string default_upscaler_weights(UpscaleMethod method) {
  const char* name = method == UpscaleMethod::nsrr      ? "upscaler_nsrr.kdw"
                     : method == UpscaleMethod::nsrr_rt ? "upscaler_nsrr_rt.kdw"
                                                        : "upscaler.kdw";
  if (const char* dir = std::getenv("KESTREL_WEIGHTS_DIR"); dir && *dir)
    return std::string(dir) + "/" + name;
  return std::string(KESTREL_SOURCE_DIR) + "/weights/" + name;
}

struct Upscaler::Impl {
  UpscalerOptions options;
  std::vector<nn::ConvLayer> layers;  // c1, c2, c3, head
  size_t parameters = 0;
  Times times;
  // Sizes of the current sequence (0 = none yet).
  int w = 0, h = 0;
  bool has_history = false;
  // Per-frame buffers (reused).
  std::vector<float> y, depth, motion, mdil, mu, sigma, keep, feat, grid, act0, act1, scratch, hist,
      next_hist, prev_depth;
  LowRes lr;                       // the planes above (reconstruct.h)
  float prev_jx = 0, prev_jy = 0;  // the previous frame's jitter
  Axis ax, ay;
  GridAxis gx, gy;
  std::unique_ptr<upscale::NsrrNetwork> nsrr;
  // nsrr, nsrr-rt: the learned TAAU run beside the network, its output the blend's history.
  std::unique_ptr<Upscaler> history;
  FloatImage history_out;

  void prepare(const UpscaleInput& in, const upscale::UpscaleKernels& k);
  void spatial(const UpscaleInput& in, FloatImage& out, bool cubic);
  void temporal(const UpscaleInput& in, FloatImage& out);
};

Upscaler::Upscaler(const UpscalerOptions& options) : impl_(std::make_unique<Impl>()) {
  if (options.factor != 2 && options.factor != 4)
    throw Error(ErrorCode::invalid_argument,
                fmt::format("upscale: factor must be 2 or 4, got {}", options.factor));
  impl_->options = options;
  if (options.method == UpscaleMethod::nsrr || options.method == UpscaleMethod::nsrr_rt) {
    const std::string path =
        options.weights.empty() ? default_upscaler_weights(options.method) : options.weights;
    impl_->nsrr = options.method == UpscaleMethod::nsrr
                      ? upscale::make_nsrr(path, options.factor, options.bf16)
                      : upscale::make_nsrr_rt(path, options.factor, options.bf16);
    UpscalerOptions history;  // the learned TAAU, with its default weights
    history.factor = options.factor;
    history.bf16 = options.bf16;
    impl_->history = std::make_unique<Upscaler>(history);
    impl_->parameters = impl_->nsrr->parameters() + impl_->history->parameter_count();
  }
  if (options.method == UpscaleMethod::neural) {
    const std::string path = options.weights.empty() ? default_upscaler_weights() : options.weights;
    impl_->layers = nn::load_layers(
        path, kMagic, kArchitecture,
        {{"c1", 16, kFeatures, 3}, {"c2", 16, 16, 3}, {"c3", 16, 16, 3}, {"head", kOutputs, 16, 3}},
        "upsampler");
    for (const auto& l : impl_->layers)
      impl_->parameters += size_t(l.outputs) * (size_t(l.cin) * size_t(l.ksize * l.ksize) + 1);
  }
}
Upscaler::~Upscaler() = default;
Upscaler::Upscaler(Upscaler&&) noexcept = default;
Upscaler& Upscaler::operator=(Upscaler&&) noexcept = default;

void Upscaler::reset() {
  impl_->has_history = false;
  if (impl_->nsrr) impl_->nsrr->reset();
  if (impl_->history) impl_->history->reset();
}
bool Upscaler::uses_bf16() const {
  if (impl_->nsrr) return impl_->nsrr->bf16();
  return impl_->options.method == UpscaleMethod::neural &&
         nn::conv_kernels(default_isa(), impl_->options.bf16).bf16;
}
UpscaleMethod Upscaler::method() const {
  return impl_->options.method;
}
int Upscaler::factor() const {
  return impl_->options.factor;
}
size_t Upscaler::parameter_count() const {
  return impl_->parameters;
}
Upscaler::Times Upscaler::last_times() const {
  return impl_->times;
}

FloatImage Upscaler::upscale(const UpscaleInput& input) {
  FloatImage out;
  upscale(input, out);
  return out;
}

void Upscaler::upscale(const UpscaleInput& input, FloatImage& out) {
  check_input(input);
  Impl& m = *impl_;
  const int f = m.options.factor;
  const int w = input.color->width, h = input.color->height;
  if (w != m.w || h != m.h) m.w = w, m.h = h, m.has_history = false;
  if (out.width != f * w || out.height != f * h || out.channels != 3)
    out = FloatImage(f * w, f * h, 3);
  m.times = {};
  switch (m.options.method) {
    case UpscaleMethod::bilinear:
      m.spatial(input, out, false);
      break;
    case UpscaleMethod::bicubic:
      m.spatial(input, out, true);
      break;
    case UpscaleMethod::nsrr:
    case UpscaleMethod::nsrr_rt:
      if (!input.depth || !input.motion)
        throw Error(ErrorCode::invalid_argument,
                    fmt::format("upscale: {} needs the depth and the motion vectors of every frame",
                                upscale_method_name(m.options.method)));
      {
        m.history->upscale(input, m.history_out);
        const Times ht = m.history->last_times();
        m.nsrr->run(input, m.history_out, out, m.times);
        m.times.history = ht.features + ht.network + ht.reconstruct;
        break;
      }
    default:
      m.temporal(input, out);
      break;
  }
}

void Upscaler::Impl::spatial(const UpscaleInput& in, FloatImage& out, bool cubic) {
  const Timer timer;
  const int f = options.factor;
  y.resize(size_t(w) * size_t(h) * 3 + 1);  // + 1: the 4-float loads of the last pixel
  y.back() = 0.0f;
  for (size_t p = 0; p + 1 < y.size(); ++p)
    y[p] = std::max(finite_or_zero(in.color->pixels[p]), 0.0f);
  const int W = out.width;
  parallel_rows(out.height, 4, [&](int r0, int r1) {
    for (int Y = r0; Y < r1; ++Y) {
      const float sy = (float(Y) + 0.5f) / float(f) - in.jitter_y + 0.5f;
      for (int X = 0; X < W; ++X) {
        const float sx = (float(X) + 0.5f) / float(f) - in.jitter_x + 0.5f;
        float* o = out.at(X, Y);
        if (cubic)
          store3(o, sample_catmull_rom3(y.data(), w, h, sx, sy));
        else
          sample_bilinear<3>(y.data(), w, h, sx, sy, o);
        for (int c = 0; c < 3; ++c) o[c] = std::max(o[c], 0.0f);
      }
    }
  });
  times.reconstruct = timer.ms();
}

// The low-resolution planes (LowRes): inputs in the tone-mapped space, the least-depth motion
// and the 3x3 statistics.
void Upscaler::Impl::prepare(const UpscaleInput& in, const upscale::UpscaleKernels& k) {
  const size_t n = size_t(w) * size_t(h), pad = upscale::kMaxLanes;
  for (auto [buf, planes] :
       {std::pair{&y, 3}, {&depth, 1}, {&motion, 2}, {&mdil, 2}, {&mu, 3}, {&sigma, 3}, {&keep, 1}})
    buf->resize(size_t(planes) * n + pad);
  lr.w = w, lr.h = h, lr.n = n;
  lr.y = y.data(), lr.depth = depth.data(), lr.motion = motion.data(), lr.mdil = mdil.data(),
  lr.mu = mu.data(), lr.sigma = sigma.data(), lr.keep = keep.data(), lr.feat = nullptr;
  upscale::InputArgs a{in.color->pixels.data(), in.depth ? in.depth->pixels.data() : nullptr,
                       in.motion ? in.motion->pixels.data() : nullptr,
                       in.motion ? in.motion->channels : 0, lr};
  parallel_rows(h, 8, [&](int r0, int r1) { k.input(a, r0, r1); });
  parallel_rows(h, 8, [&](int r0, int r1) { k.stats(lr, r0, r1); });
}

void Upscaler::Impl::temporal(const UpscaleInput& in, FloatImage& out) {
  const int f = options.factor;
  const int W = out.width, H = out.height;
  const bool neural = options.method == UpscaleMethod::neural;
  const upscale::UpscaleKernels& kern = upscale::upscale_kernels(default_isa());
  Timer timer;
  prepare(in, kern);
  const size_t n = size_t(w) * size_t(h);
  if (has_history &&
      (hist.size() != size_t(W) * size_t(H) * 3 + 1 || prev_depth.size() != depth.size()))
    has_history = false;
  HistoryArgs ha{lr,          prev_depth.data(), hist.data(), W,       H,          f,
                 in.jitter_x, in.jitter_y,       prev_jx,     prev_jy, has_history};
  // Parameters on the grid (gw x gh, 3 per cell): the network's, decoded, or the constants.
  const int gw = f == 2 ? (w + 1) / 2 : w, gh = f == 2 ? (h + 1) / 2 : h;
  grid.resize(size_t(gw) * size_t(gh) * 3);
  if (neural) {
    // Low-resolution features (model.features), then pooled onto the grid (pool_features).
    feat.resize(n * kLowFeatures + upscale::kMaxLanes);
    ha.lr.feat = feat.data();
    parallel_rows(h, 8, [&](int r0, int r1) { kern.features(ha, r0, r1); });
    act0.resize(size_t(gw) * size_t(gh) * kFeatures);
    const int s = f == 2 ? 2 : 1;
    parallel_rows(gh, 8, [&](int r0, int r1) {
      for (int gj = r0; gj < r1; ++gj)
        for (int gi = 0; gi < gw; ++gi) {
          float* o = &act0[(size_t(gj) * size_t(gw) + size_t(gi)) * kFeatures];
          float sum[kLowFeatures] = {}, mx1 = 0, mx4 = 0;
          for (int b = 0; b < s; ++b)
            for (int a = 0; a < s; ++a) {
              const size_t q = size_t(clampi(s * gj + b, 0, h - 1)) * size_t(w) +
                               size_t(clampi(s * gi + a, 0, w - 1));
              for (size_t k = 0; k < size_t(kLowFeatures); ++k) sum[k] += feat[k * n + q];
              mx1 = std::max(mx1, std::fabs(feat[n + q])),
              mx4 = std::max(mx4, std::fabs(feat[4 * n + q]));
            }
          const float inv = 1.0f / float(s * s);
          for (int k = 0; k < kLowFeatures; ++k) o[k] = sum[k] * inv;
          o[8] = mx1, o[9] = mx4, o[10] = float(f) / 4.0f;
        }
    });
    times.features = timer.ms();
    timer = Timer();
    const nn::ConvKernels& k = nn::conv_kernels(default_isa(), options.bf16);
    k.conv(layers[0], act0, gw, gh, act1, true, scratch);
    k.conv(layers[1], act1, gw, gh, act0, true, scratch);
    k.conv(layers[2], act0, gw, gh, act1, true, scratch);
    k.conv(layers[3], act1, gw, gh, act0, false, scratch);
    const int stride = layers[3].cout;
    // The parameters decoded (libm's exp and log1p: ~1 ms for 320 x 180 cells, so in parallel).
    parallel_for(0, size_t(gw) * size_t(gh), 2048, [&](size_t q0, size_t q1) {
      for (size_t q = q0; q < q1; ++q) {
        const float* p = &act0[q * size_t(stride)];
        grid[3 * q] = sigmoid(p[0]), grid[3 * q + 1] = softplus(p[1]),
                 grid[3 * q + 2] = softplus(p[2]);
      }
    });
    times.network = timer.ms();
    timer = Timer();
  } else {
    for (size_t q = 0; q < size_t(gw) * size_t(gh); ++q)
      grid[3 * q] = kTaauA, grid[3 * q + 1] = kTaauGamma, grid[3 * q + 2] = kTaauKappa;
    times.features = timer.ms();
    timer = Timer();
  }
  // Reconstruction (model.step): per output pixel.
  if (has_history) parallel_rows(h, 8, [&](int r0, int r1) { kern.disocclusion(ha, r0, r1); });
  ax.build(W, w, f, in.jitter_x, kCurrentSharpness),
      ay.build(H, h, f, in.jitter_y, kCurrentSharpness);
  gx.build(W, gw), gy.build(H, gh);
  next_hist.resize(size_t(W) * size_t(H) * 3 + 1);  // three planes, every pixel written
  next_hist.back() = 0.0f;
  Recon r;
  r.lr = lr, r.grid = grid.data();
  r.hist = hist.data(), r.next = next_hist.data(), r.out = out.pixels.data();
  r.ax = &ax, r.ay = &ay, r.gx = &gx, r.gy = &gy;
  r.W = W, r.H = H, r.gw = gw, r.f = f, r.history = has_history;
  parallel_rows(H, 4, [&](int r0, int r1) { kern.reconstruct(r, r0, r1); });
  hist.swap(next_hist);
  prev_depth.swap(depth);  // prepare() rewrites every pixel of depth next frame
  prev_jx = in.jitter_x, prev_jy = in.jitter_y;
  has_history = true;
  times.reconstruct = timer.ms();
}

}  // namespace kestrel
