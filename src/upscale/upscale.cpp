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
using upscale::Recon;

namespace {

constexpr float kLuma[3] = {0.2126f, 0.7152f, 0.0722f};
constexpr int kFeatures = 11, kLowFeatures = 8, kOutputs = 3;
constexpr float kCurrentSharpness = 2.0f;
constexpr float kMinDepth = 1e-3f, kMaxMotion = 65536.0f;
// History is dropped where no previous depth around the reprojected position is within this
// fraction of the current depth (the denoisers' test) plus the depth's slope: a disocclusion.
constexpr float kDisocclusion = 0.1f;
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
ReconstructFn reconstruct_for(Isa isa) {
  require_supported(isa);
  switch (isa) {
    case Isa::avx512:
      return reconstruct_avx512();
    case Isa::avx2:
      return reconstruct_avx2();
    default:
      return reconstruct_sse2();
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
  std::vector<float> y, depth, mdil, mu, sigma, feat, grid, act0, act1, scratch, hist, next_hist,
      prev_depth;
  std::vector<uint8_t> keep;       // per low-resolution pixel: not disoccluded (disocclusion())
  float prev_jx = 0, prev_jy = 0;  // the previous frame's jitter
  Axis ax, ay;
  GridAxis gx, gy;
  std::unique_ptr<upscale::NsrrNetwork> nsrr;

  void prepare(const UpscaleInput& in);
  void spatial(const UpscaleInput& in, FloatImage& out, bool cubic);
  void temporal(const UpscaleInput& in, FloatImage& out);
  void disocclusion(float jx, float jy);
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
    impl_->parameters = impl_->nsrr->parameters();
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
}
bool Upscaler::uses_bf16() const {
  return impl_->nsrr && impl_->nsrr->bf16();
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
      m.nsrr->run(input, out, m.times);
      break;
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

// Inputs in the tone-mapped space, the least-depth motion, the 3x3 statistics and (for the
// network) the low-resolution features pooled onto the grid.
void Upscaler::Impl::prepare(const UpscaleInput& in) {
  const size_t n = size_t(w) * size_t(h);
  // + 1: room for the reconstruction's 4-float loads of the last pixel.
  y.resize(3 * n + 1), depth.resize(n), mdil.resize(2 * n), mu.resize(3 * n + 1),
      sigma.resize(3 * n + 1);
  y[3 * n] = mu[3 * n] = sigma[3 * n] = 0.0f;
  std::vector<float>& motion = scratch;  // raw motion, reused below as conv scratch
  motion.resize(2 * n);
  const int mc = in.motion ? in.motion->channels : 0;
  parallel_rows(h, 8, [&](int r0, int r1) {
    for (size_t p = size_t(r0) * size_t(w); p < size_t(r1) * size_t(w); ++p) {
      float c[3];
      for (int k = 0; k < 3; ++k)
        c[k] = std::max(finite_or_zero(in.color->pixels[3 * p + size_t(k)]), 0.0f);
      const float s = 1.0f / (1.0f + luma(c));
      for (int k = 0; k < 3; ++k) y[3 * p + size_t(k)] = c[k] * s;
      depth[p] = in.depth ? std::max(finite_or_zero(in.depth->pixels[p]), 0.0f) : 1.0f;
      for (int k = 0; k < 2; ++k)  // beyond any frame, and safe to convert to int
        motion[2 * p + size_t(k)] =
            mc ? std::clamp(finite_or_zero(in.motion->pixels[size_t(mc) * p + size_t(k)]),
                            -kMaxMotion, kMaxMotion)
               : 0.0f;
    }
  });
  parallel_rows(h, 8, [&](int r0, int r1) {
    std::vector<float> c1(3 * size_t(w)), c2(3 * size_t(w));  // vertical 3-sums of y and y^2
    for (int j = r0; j < r1; ++j) {
      const float* rows[3] = {&y[size_t(clampi(j - 1, 0, h - 1)) * size_t(w) * 3],
                              &y[size_t(j) * size_t(w) * 3],
                              &y[size_t(clampi(j + 1, 0, h - 1)) * size_t(w) * 3]};
      for (size_t q = 0; q < 3 * size_t(w); ++q) {
        const float a = rows[0][q], b = rows[1][q], c = rows[2][q];
        c1[q] = a + b + c, c2[q] = a * a + b * b + c * c;
      }
      const float* drow[3] = {&depth[size_t(clampi(j - 1, 0, h - 1)) * size_t(w)],
                              &depth[size_t(j) * size_t(w)],
                              &depth[size_t(clampi(j + 1, 0, h - 1)) * size_t(w)]};
      const int row_of[3] = {clampi(j - 1, 0, h - 1), j, clampi(j + 1, 0, h - 1)};
      for (int i = 0; i < w; ++i) {
        const size_t p = size_t(j) * size_t(w) + size_t(i);
        const int cols[3] = {clampi(i - 1, 0, w - 1), i, clampi(i + 1, 0, w - 1)};
        // The least depth (0 = sky, farthest); the first of equals in row-major order.
        float best = 3e38f;
        size_t arg = p;
        for (int b = 0; b < 3; ++b)
          for (int a = 0; a < 3; ++a) {
            const float d0 = drow[b][cols[a]];
            const float d = d0 > 0 ? d0 : 3e38f;
            if (d < best) best = d, arg = size_t(row_of[b]) * size_t(w) + size_t(cols[a]);
          }
        mdil[2 * p] = motion[2 * arg], mdil[2 * p + 1] = motion[2 * arg + 1];
        for (int k = 0; k < 3; ++k) {
          const float s1 = c1[3 * size_t(cols[0]) + size_t(k)] + c1[3 * size_t(i) + size_t(k)] +
                           c1[3 * size_t(cols[2]) + size_t(k)];
          const float s2 = c2[3 * size_t(cols[0]) + size_t(k)] + c2[3 * size_t(i) + size_t(k)] +
                           c2[3 * size_t(cols[2]) + size_t(k)];
          const float m = s1 / 9.0f;
          mu[3 * p + size_t(k)] = m;
          sigma[3 * p + size_t(k)] = std::sqrt(std::max(s2 / 9.0f - m * m, 0.0f));
        }
      }
    }
  });
}

// keep[p] = 1 where the history of low-resolution pixel p shows the surface p shows: one of
// the four previous samples around where p's sample was (its position plus m, the least-depth
// motion the history is fetched with, in the previous frame's sample grid, jitter included;
// edges clamped) has a depth within kDisocclusion of p's plus p's depth slope (the change to
// the next sample on the smoother side, in x plus in y: at most a pixel separates the two
// frames' samples), or both are sky. (model.keep_history)
void Upscaler::Impl::disocclusion(float jx, float jy) {
  keep.resize(size_t(w) * size_t(h));
  parallel_rows(h, 8, [&](int r0, int r1) {
    for (int j = r0; j < r1; ++j) {
      const float* up = &depth[size_t(clampi(j - 1, 0, h - 1)) * size_t(w)];
      const float* mid = &depth[size_t(j) * size_t(w)];
      const float* down = &depth[size_t(clampi(j + 1, 0, h - 1)) * size_t(w)];
      for (int i = 0; i < w; ++i) {
        const size_t p = size_t(j) * size_t(w) + size_t(i);
        const float d = mid[i];
        // The depth's change to the next sample on the smoother side, in x and in y: a
        // surface seen at a grazing angle changes that much between neighbouring samples.
        const float left = std::fabs(mid[clampi(i - 1, 0, w - 1)] - d),
                    right = std::fabs(mid[clampi(i + 1, 0, w - 1)] - d);
        const float above = std::fabs(up[i] - d), below = std::fabs(down[i] - d);
        const float slope = std::min(left, right) + std::min(above, below);
        const float tol = kDisocclusion * std::max(d, kMinDepth) + slope;
        const int qx = floor_int(float(i) + jx + mdil[2 * p] - prev_jx);
        const int qy = floor_int(float(j) + jy + mdil[2 * p + 1] - prev_jy);
        const bool sky = !(d > 0);
        bool same = false;
        for (int b = 0; b <= 1; ++b) {
          const float* row = &prev_depth[size_t(clampi(qy + b, 0, h - 1)) * size_t(w)];
          for (int a = 0; a <= 1; ++a) {
            const float dq = row[clampi(qx + a, 0, w - 1)];
            // Both surfaces within tol, or both sky (depths are >= 0).
            same |= (sky == !(dq > 0)) & (sky | (std::fabs(dq - d) <= tol));
          }
        }
        keep[p] = same;
      }
    }
  });
}

void Upscaler::Impl::temporal(const UpscaleInput& in, FloatImage& out) {
  const int f = options.factor;
  const int W = out.width, H = out.height;
  const bool neural = options.method == UpscaleMethod::neural;
  Timer timer;
  prepare(in);
  if (has_history &&
      (hist.size() != size_t(W) * size_t(H) * 3 + 1 || prev_depth.size() != size_t(w) * size_t(h)))
    has_history = false;
  // Parameters on the grid (gw x gh, 3 per cell): the network's, decoded, or the constants.
  const int gw = f == 2 ? (w + 1) / 2 : w, gh = f == 2 ? (h + 1) / 2 : h;
  grid.resize(size_t(gw) * size_t(gh) * 3);
  if (neural) {
    // Low-resolution features (model.features), then pooled onto the grid (pool_features).
    const size_t n = size_t(w) * size_t(h);
    feat.resize(n * kLowFeatures);
    const float* hp = hist.data();
    parallel_rows(h, 8, [&](int r0, int r1) {
      for (int j = r0; j < r1; ++j)
        for (int i = 0; i < w; ++i) {
          const size_t p = size_t(j) * size_t(w) + size_t(i);
          const float L = luma(&y[3 * p]), muL = luma(&mu[3 * p]), sigL = luma(&sigma[3 * p]);
          const float mx = mdil[2 * p], my = mdil[2 * p + 1];
          float valid = 0, Lh = L, dchange = 0;
          if (has_history) {
            const float hx = float(f) * (float(i) + in.jitter_x + mx),
                        hy = float(f) * (float(j) + in.jitter_y + my);
            valid = (hx >= 0 && hx < float(W) && hy >= 0 && hy < float(H)) ? 1.0f : 0.0f;
            float hc[3];  // the history is planar (reconstruct.h)
            for (size_t c = 0; c < 3; ++c)
              sample_bilinear<1>(hp + c * size_t(W) * size_t(H), W, H, hx, hy, &hc[c]);
            Lh = luma(hc);
            const int px = clampi(floor_int(float(i) + 0.5f + mx), 0, w - 1);
            const int py = clampi(floor_int(float(j) + 0.5f + my), 0, h - 1);
            const float dp = prev_depth[size_t(py) * size_t(w) + size_t(px)], d = depth[p];
            if (d > 0 && dp > 0)
              dchange = std::clamp((dp - d) / std::max(d, kMinDepth), -1.0f, 1.0f);
            else if ((d > 0) != (dp > 0))
              dchange = 1.0f;
          }
          const float mmag = std::min(std::sqrt(mx * mx + my * my) / 8.0f, 1.0f);
          const float d = depth[p];
          float edge = 0;
          const int nb[4][2] = {{0, -1}, {-1, 0}, {1, 0}, {0, 1}};
          for (const auto& o : nb) {
            const float dn = depth[size_t(clampi(j + o[1], 0, h - 1)) * size_t(w) +
                                   size_t(clampi(i + o[0], 0, w - 1))];
            edge = std::max(edge, std::fabs(dn - d));
          }
          edge = std::min(edge / std::max(d, kMinDepth), 1.0f);
          float* o = &feat[p * kLowFeatures];
          o[0] = L, o[1] = (Lh - L) * valid, o[2] = sigL, o[3] = (Lh - muL) * valid,
          o[4] = dchange * valid;
          o[5] = mmag, o[6] = valid, o[7] = edge;
        }
    });
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
              const float* fq = &feat[q * kLowFeatures];
              for (int k = 0; k < kLowFeatures; ++k) sum[k] += fq[k];
              mx1 = std::max(mx1, std::fabs(fq[1])), mx4 = std::max(mx4, std::fabs(fq[4]));
            }
          const float inv = 1.0f / float(s * s);
          for (int k = 0; k < kLowFeatures; ++k) o[k] = sum[k] * inv;
          o[8] = mx1, o[9] = mx4, o[10] = float(f) / 4.0f;
        }
    });
    times.features = timer.ms();
    timer = Timer();
    const nn::ConvKernels& k = nn::conv_kernels(default_isa());
    k.conv(layers[0], act0, gw, gh, act1, true, scratch);
    k.conv(layers[1], act1, gw, gh, act0, true, scratch);
    k.conv(layers[2], act0, gw, gh, act1, true, scratch);
    k.conv(layers[3], act1, gw, gh, act0, false, scratch);
    const int stride = layers[3].cout;
    for (size_t q = 0; q < size_t(gw) * size_t(gh); ++q) {
      const float* p = &act0[q * size_t(stride)];
      grid[3 * q] = sigmoid(p[0]), grid[3 * q + 1] = softplus(p[1]),
               grid[3 * q + 2] = softplus(p[2]);
    }
    times.network = timer.ms();
    timer = Timer();
  } else {
    for (size_t q = 0; q < size_t(gw) * size_t(gh); ++q)
      grid[3 * q] = kTaauA, grid[3 * q + 1] = kTaauGamma, grid[3 * q + 2] = kTaauKappa;
    times.features = timer.ms();
    timer = Timer();
  }
  // Reconstruction (model.step): per output pixel.
  if (has_history) disocclusion(in.jitter_x, in.jitter_y);
  ax.build(W, w, f, in.jitter_x, kCurrentSharpness),
      ay.build(H, h, f, in.jitter_y, kCurrentSharpness);
  gx.build(W, gw), gy.build(H, gh);
  next_hist.resize(size_t(W) * size_t(H) * 3 + 1);  // three planes, every pixel written
  next_hist.back() = 0.0f;
  Recon r;
  r.y = y.data(), r.mdil = mdil.data(), r.mu = mu.data(), r.sigma = sigma.data(),
  r.grid = grid.data();
  r.hist = hist.data(), r.next = next_hist.data(), r.out = out.pixels.data();
  r.keep = keep.data();
  r.ax = &ax, r.ay = &ay, r.gx = &gx, r.gy = &gy;
  r.w = w, r.h = h, r.W = W, r.H = H, r.gw = gw, r.f = f, r.history = has_history;
  const upscale::ReconstructFn reconstruct_rows = upscale::reconstruct_for(default_isa());
  parallel_rows(H, 4, [&](int r0, int r1) { reconstruct_rows(r, r0, r1); });
  hist.swap(next_hist);
  prev_depth.swap(depth);  // prepare() rewrites every pixel of depth next frame
  prev_jx = in.jitter_x, prev_jy = in.jitter_y;
  has_history = true;
  times.reconstruct = timer.ms();
}

}  // namespace kestrel
