// kestrel::Denoiser: input checks and padding, the neural denoiser's state, and the two
// non-neural baselines (edge-avoiding a-trous, SVGF-like).
#include "kestrel/denoise.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <filesystem>

#include "core/parallel.h"
#include "denoise/kernels.h"
#include "denoise/neural.h"
#include "kestrel/error.h"
#include "kestrel/trace.h"

#ifndef KESTREL_SOURCE_DIR
#define KESTREL_SOURCE_DIR "."
#endif

namespace kestrel {

namespace denoise {
// The table of the ISA in force now (default_isa(): --isa, KESTREL_ISA or set_default_isa),
// looked up per call, not cached: a later set_default_isa takes effect, as in traversal.
const KernelTable& host_kernels() {
  switch (default_isa()) {
    case Isa::avx512:
      return kernels_avx512();
    case Isa::avx2:
      return kernels_avx2();
    default:
      return kernels_sse2();
  }
}
}  // namespace denoise

using denoise::Planes;

const char* denoise_method_name(DenoiseMethod m) {
  switch (m) {
    case DenoiseMethod::neural:
      return "neural";
    case DenoiseMethod::svgf:
      return "svgf";
    case DenoiseMethod::atrous:
      return "atrous";
  }
  return "?";
}

std::optional<DenoiseMethod> denoise_method_from_name(std::string_view name) {
  for (DenoiseMethod m : {DenoiseMethod::neural, DenoiseMethod::svgf, DenoiseMethod::atrous})
    if (name == denoise_method_name(m)) return m;
  return std::nullopt;
}

std::string default_denoiser_weights() {
  if (const char* dir = std::getenv("KESTREL_WEIGHTS_DIR"); dir && *dir)
    return std::string(dir) + "/denoiser.kdw";
  return std::string(KESTREL_SOURCE_DIR) + "/weights/denoiser.kdw";
}

namespace {

template <class F>
void rows(int h, F&& f) {
  parallel_for(0, size_t(h), 4, [&](size_t begin, size_t end) { f(int(begin), int(end)); });
}

// Fills every plane of `p` outside its top-left width x height region by edge replication
// (the padding of the inputs and of the neural denoiser's state).
void replicate_edges(Planes& p, int width, int height) {
  if (width == p.width && height == p.height) return;
  rows(p.height, [&](int r0, int r1) {
    for (int c = 0; c < p.channels; ++c)
      for (int y = r0; y < r1; ++y) {
        float* dst = p.ch(c) + size_t(y) * size_t(p.width);
        if (y >= height)
          std::memcpy(dst, p.ch(c) + size_t(height - 1) * size_t(p.width),
                      sizeof(float) * size_t(width));
        std::fill(dst + width, dst + p.width, dst[width - 1]);
      }
  });
}

// The inputs as padded planes (multiple of `align`, edge replicated): colour 0-2, albedo
// 3-5, normal 6-8, depth 9, roughness 10, motion 11-12; NaN/Inf to 0, negative colour to 0;
// absent images: albedo 1, normal 0, depth 1, roughness 0, motion 0. `p` is reused.
void gather(const DenoiseInput& in, int align, Planes& p) {
  if (!in.color) throw Error(ErrorCode::invalid_argument, "denoise: no colour image");
  const FloatImage& c = *in.color;
  if (c.width <= 0 || c.height <= 0 ||
      c.pixels.size() != size_t(c.width) * size_t(c.height) * size_t(c.channels))
    throw Error(
        ErrorCode::invalid_argument,
        fmt::format("denoise: colour image is empty or malformed ({}x{})", c.width, c.height));
  if (c.channels < 3)
    throw Error(ErrorCode::invalid_argument,
                fmt::format("denoise: colour has {} channels, needs 3", c.channels));
  auto check = [&](const FloatImage* img, const char* name, int min_channels) {
    if (!img) return;
    if (img->width != c.width || img->height != c.height)
      throw Error(ErrorCode::invalid_argument,
                  fmt::format("denoise: {} is {}x{}, colour is {}x{}", name, img->width,
                              img->height, c.width, c.height));
    if (img->channels < min_channels ||
        img->pixels.size() != size_t(img->width) * size_t(img->height) * size_t(img->channels))
      throw Error(ErrorCode::invalid_argument, fmt::format("denoise: {} has {} channels, needs {}",
                                                           name, img->channels, min_channels));
  };
  check(in.albedo, "albedo", 3);
  check(in.normal, "normal", 3);
  check(in.depth, "depth", 1);
  check(in.roughness, "roughness", 1);
  check(in.motion, "motion", 2);
  const int W = (c.width + align - 1) / align * align, H = (c.height + align - 1) / align * align;
  if (p.width != W || p.height != H || p.channels != 13) p = Planes(W, H, 13);
  struct Source {
    const FloatImage* img;
    int first, count;
    float fallback;
  };
  const Source sources[] = {{in.color, 0, 3, 0.0f},      {in.albedo, 3, 3, 1.0f},
                            {in.normal, 6, 3, 0.0f},     {in.depth, 9, 1, 1.0f},
                            {in.roughness, 10, 1, 0.0f}, {in.motion, 11, 2, 0.0f}};
  const int cw = c.width;
  rows(c.height, [&](int r0, int r1) {
    for (int y = r0; y < r1; ++y) {
      const size_t row = size_t(y) * size_t(W);
      for (const Source& s : sources)
        for (int k = 0; k < s.count; ++k) {
          float* dst = p.ch(s.first + k) + row;
          if (!s.img) {
            std::fill(dst, dst + cw, s.fallback);
            continue;
          }
          const int stride = s.img->channels;
          const float* src =
              s.img->pixels.data() + size_t(y) * size_t(cw) * size_t(stride) + size_t(k);
          const bool colour = s.first == 0;
          for (int x = 0; x < cw; ++x) {
            const float v = src[size_t(x) * size_t(stride)];
            const float finite = v - v == 0.0f ? v : 0.0f;     // NaN and +-Inf to 0
            dst[x] = colour && finite < 0.0f ? 0.0f : finite;  // negative colour to 0
          }
        }
    }
  });
  replicate_edges(p, cw, c.height);
}

void to_image(const Planes& p, int width, int height, FloatImage& out) {
  if (out.width != width || out.height != height || out.channels != 3)
    out = FloatImage(width, height, 3);
  rows(height, [&](int r0, int r1) {
    for (int y = r0; y < r1; ++y) {
      const size_t row = size_t(y) * size_t(p.width);
      float* o = out.at(0, y);
      for (int c = 0; c < 3; ++c) {
        const float* s = p.ch(c) + row;
        for (int x = 0; x < width; ++x) o[size_t(x) * 3 + size_t(c)] = s[x];
      }
    }
  });
}

Planes gather(const DenoiseInput& in, int align) {
  Planes p;
  gather(in, align, p);
  return p;
}

constexpr float kEps = denoise::kAlbedoEps;
const float kB3[5] = {1.0f / 16, 1.0f / 4, 3.0f / 8, 1.0f / 4, 1.0f / 16};

float luminance(float r, float g, float b) {
  return 0.2126f * r + 0.7152f * g + 0.0722f * b;
}

// One 5x5 edge-avoiding a-trous pass (B3 spline) over planar irradiance `x` (3 channels) and
// optionally a variance plane; weights from the caller's per-pixel edge function.
template <class Weight>
void atrous_pass(const Planes& in, Planes& out, const Planes& g, int dilation, const float* var_in,
                 float* var_out, Weight&& weight) {
  const int W = in.width, H = in.height;
  rows(H, [&](int r0, int r1) {
    for (int y = r0; y < r1; ++y)
      for (int x = 0; x < W; ++x) {
        const size_t p = size_t(y) * size_t(W) + size_t(x);
        float acc[3] = {0, 0, 0}, wsum = 0, vacc = 0;
        for (int j = -2; j <= 2; ++j) {
          const int qy = y + j * dilation;
          if (qy < 0 || qy >= H) continue;
          for (int i = -2; i <= 2; ++i) {
            const int qx = x + i * dilation;
            if (qx < 0 || qx >= W) continue;
            const size_t q = size_t(qy) * size_t(W) + size_t(qx);
            const float w = kB3[j + 2] * kB3[i + 2] * weight(p, q, in, g);
            for (int c = 0; c < 3; ++c) acc[c] += w * in.ch(c)[q];
            wsum += w;
            if (var_in) vacc += w * w * var_in[q];
          }
        }
        for (int c = 0; c < 3; ++c) out.ch(c)[p] = wsum > 0 ? acc[c] / wsum : in.ch(c)[p];
        if (var_out) var_out[p] = wsum > 0 ? vacc / (wsum * wsum) : var_in[p];
      }
  });
}

// x^(2^k) by k squarings (SVGF's normal weight max(0, n.n_q)^128 without pow).
float pow2k(float x, int k) {
  for (int i = 0; i < k; ++i) x *= x;
  return x;
}

float normal_dot(const Planes& g, size_t p, size_t q) {
  return g.ch(6)[p] * g.ch(6)[q] + g.ch(7)[p] * g.ch(7)[q] + g.ch(8)[p] * g.ch(8)[q];
}
float rel_depth(const Planes& g, size_t p, size_t q) {
  return std::abs(g.ch(9)[p] - g.ch(9)[q]) / std::max(g.ch(9)[p], denoise::kMinDepth);
}

// SVGF's depth edge stop: |z_p - z_q| / (|grad z(p) . (p - q)| + eps), the screen-space depth
// gradient (central differences) predicting the depth change along the tap's offset.
struct DepthGradient {
  std::vector<float> gx, gy;
  int width = 0;
  explicit DepthGradient(const Planes& g)
      : gx(size_t(g.width) * size_t(g.height)), gy(gx.size()), width(g.width) {
    const int W = g.width, H = g.height;
    const float* z = g.ch(9);
    for (int y = 0; y < H; ++y)
      for (int x = 0; x < W; ++x) {
        const size_t p = size_t(y) * size_t(W) + size_t(x);
        const int xl = std::max(x - 1, 0), xr = std::min(x + 1, W - 1), yu = std::max(y - 1, 0),
                  yd = std::min(y + 1, H - 1);
        gx[p] = (z[size_t(y) * size_t(W) + size_t(xr)] - z[size_t(y) * size_t(W) + size_t(xl)]) /
                float(std::max(xr - xl, 1));
        gy[p] = (z[size_t(yd) * size_t(W) + size_t(x)] - z[size_t(yu) * size_t(W) + size_t(x)]) /
                float(std::max(yd - yu, 1));
      }
  }
  float weight(const Planes& g, size_t p, size_t q, float sigma) const {
    const float dx = float(int(q % size_t(width)) - int(p % size_t(width)));
    const float dy = float(int(q / size_t(width)) - int(p / size_t(width)));
    const float predicted = std::abs(gx[p] * dx + gy[p] * dy);
    return std::abs(g.ch(9)[p] - g.ch(9)[q]) /
           (sigma * predicted + 1e-3f * std::max(g.ch(9)[p], denoise::kMinDepth));
  }
};

// The baselines' demodulation: by albedo, except where the albedo is (nearly) black
// (emitters, black surfaces): there the colour is filtered as it is, since dividing by ~0
// would turn it into huge irradiance that the filters then spread onto lit neighbours.
float demod_albedo(const Planes& g, size_t p, int c) {
  const float a0 = g.ch(3)[p], a1 = g.ch(4)[p], a2 = g.ch(5)[p];
  if (std::max(a0, std::max(a1, a2)) < 0.02f) return 1.0f;
  return std::max(g.ch(3 + c)[p], 0.0f) + kEps;
}

Planes demodulate(const Planes& g) {
  Planes x(g.width, g.height, 3);
  for (size_t p = 0; p < size_t(g.width) * size_t(g.height); ++p)
    for (int c = 0; c < 3; ++c) x.ch(c)[p] = g.ch(c)[p] / demod_albedo(g, p, c);
  return x;
}

Planes remodulate(const Planes& x, const Planes& g) {
  Planes out(g.width, g.height, 3);
  for (size_t p = 0; p < size_t(g.width) * size_t(g.height); ++p)
    for (int c = 0; c < 3; ++c) out.ch(c)[p] = std::max(x.ch(c)[p], 0.0f) * demod_albedo(g, p, c);
  return out;
}

// Dammertz et al. 2010 on demodulated irradiance: 5 passes, dilation 1..16, colour
// (log irradiance) / normal / depth (SVGF's gradient-scaled form) edge stopping; the colour
// sigma halves each pass.
Planes atrous_filter(const Planes& g) {
  Planes x = demodulate(g), t(g.width, g.height, 3), logx(g.width, g.height, 3);
  const DepthGradient dz(g);
  const float sigma_c = 0.6f, sigma_n = 0.2f, sigma_z = 1.0f;
  for (int it = 0; it < 5; ++it) {
    for (size_t p = 0; p < x.data.size(); ++p) logx.data[p] = std::log1p(std::max(x.data[p], 0.0f));
    const float sc = sigma_c * std::ldexp(1.0f, -it);
    atrous_pass(x, t, g, 1 << it, nullptr, nullptr,
                [&](size_t p, size_t q, const Planes&, const Planes& gg) {
                  float d2 = 0;
                  for (int c = 0; c < 3; ++c) {
                    const float d = logx.ch(c)[p] - logx.ch(c)[q];
                    d2 += d * d;
                  }
                  const float nd = std::max(0.0f, 1.0f - normal_dot(gg, p, q));
                  return std::exp(-d2 / (sc * sc) - nd / (sigma_n * sigma_n) -
                                  dz.weight(gg, p, q, sigma_z));
                });
    std::swap(x, t);
  }
  return remodulate(x, g);
}

// SVGF-like (Schied et al. 2017): temporal accumulation of demodulated irradiance and its
// luminance moments with motion-vector reprojection and a depth/normal consistency test,
// variance from the moments (a spatial estimate for short histories), 5 variance-guided
// a-trous passes; the first pass's output is the next frame's history.
struct Svgf {
  Planes history;  // irradiance 0-2, moments 3-4, length 5, depth 6, normal 7-9
  Planes run(const Planes& g) {
    const int W = g.width, H = g.height;
    const size_t N = size_t(W) * size_t(H);
    Planes x = demodulate(g);
    const bool have = history.width == W && history.height == H;
    Planes acc(W, H, 3);
    std::vector<float> m1(N), m2(N), len(N), var(N);
    rows(H, [&](int r0, int r1) {
      for (int y = r0; y < r1; ++y)
        for (int i = 0; i < W; ++i) {
          const size_t p = size_t(y) * size_t(W) + size_t(i);
          const float l = luminance(x.ch(0)[p], x.ch(1)[p], x.ch(2)[p]);
          float h[5] = {0, 0, 0, 0, 0}, hl = 0;
          if (have) {
            // Bilinear reprojection using only the consistent taps (depth within 10 %,
            // normals within ~25 degrees).
            const float px = float(i) + g.ch(11)[p], py = float(y) + g.ch(12)[p];
            const int x0 = int(std::floor(px)), y0 = int(std::floor(py));
            const float fx = px - float(x0), fy = py - float(y0);
            float wsum = 0;
            for (int k = 0; k < 4; ++k) {
              const int sx = x0 + (k & 1), sy = y0 + (k >> 1);
              if (sx < 0 || sy < 0 || sx >= W || sy >= H) continue;
              const size_t q = size_t(sy) * size_t(W) + size_t(sx);
              const float zq = history.ch(6)[q], z = g.ch(9)[p];
              const float nd = g.ch(6)[p] * history.ch(7)[q] + g.ch(7)[p] * history.ch(8)[q] +
                               g.ch(8)[p] * history.ch(9)[q];
              const bool normals =
                  (g.ch(6)[p] == 0 && g.ch(7)[p] == 0 && g.ch(8)[p] == 0) || nd > 0.9f;
              if (std::abs(zq - z) > 0.1f * std::max(z, denoise::kMinDepth) || !normals) continue;
              const float w = ((k & 1) ? fx : 1 - fx) * ((k >> 1) ? fy : 1 - fy);
              for (int c = 0; c < 5; ++c) h[c] += w * history.ch(c)[q];
              hl += w * history.ch(5)[q];
              wsum += w;
            }
            if (wsum > 1e-3f) {
              for (float& v : h) v /= wsum;
              hl /= wsum;
            } else {
              hl = 0;
            }
          }
          const float n = std::min(hl, 254.0f) + 1.0f;
          const float a = std::max(1.0f / n, 0.2f);
          for (int c = 0; c < 3; ++c)
            acc.ch(c)[p] = hl > 0 ? h[c] + a * (x.ch(c)[p] - h[c]) : x.ch(c)[p];
          m1[p] = hl > 0 ? h[3] + a * (l - h[3]) : l;
          m2[p] = hl > 0 ? h[4] + a * (l * l - h[4]) : l * l;
          len[p] = n;
          var[p] = std::max(0.0f, m2[p] - m1[p] * m1[p]);
        }
    });
    // Short histories: variance from a 7x7 neighbourhood of the moments.
    std::vector<float> var2 = var;
    rows(H, [&](int r0, int r1) {
      for (int y = r0; y < r1; ++y)
        for (int i = 0; i < W; ++i) {
          const size_t p = size_t(y) * size_t(W) + size_t(i);
          if (len[p] >= 4) continue;
          float s1 = 0, s2 = 0, ws = 0;
          for (int j = -3; j <= 3; ++j)
            for (int k = -3; k <= 3; ++k) {
              const int sy = y + j, sx = i + k;
              if (sx < 0 || sy < 0 || sx >= W || sy >= H) continue;
              const size_t q = size_t(sy) * size_t(W) + size_t(sx);
              const float w = std::exp(-rel_depth(g, p, q) / 0.05f) *
                                  pow2k(std::max(0.0f, normal_dot(g, p, q)), 5) +
                              (q == p ? 1.0f : 0.0f);
              s1 += w * m1[q], s2 += w * m2[q], ws += w;
            }
          var2[p] = std::max(0.0f, s2 / ws - (s1 / ws) * (s1 / ws)) * 4.0f / len[p];
        }
    });
    var = var2;
    Planes t(W, H, 3);
    std::vector<float> var_next(N), gvar(N);
    const float sigma_l = 4.0f, sigma_z = 1.0f;  // sigma_n = 128 = 2^7 (pow2k below)
    const DepthGradient dz(g);
    Planes first;
    for (int it = 0; it < 5; ++it) {
      // 3x3 Gaussian-blurred variance for the luminance edge stop.
      rows(H, [&](int r0, int r1) {
        for (int y = r0; y < r1; ++y)
          for (int i = 0; i < W; ++i) {
            float s = 0, ws = 0;
            for (int j = -1; j <= 1; ++j)
              for (int k = -1; k <= 1; ++k) {
                const int sy = y + j, sx = i + k;
                if (sx < 0 || sy < 0 || sx >= W || sy >= H) continue;
                const float w = (j == 0 ? 0.5f : 0.25f) * (k == 0 ? 0.5f : 0.25f);
                s += w * var[size_t(sy) * size_t(W) + size_t(sx)], ws += w;
              }
            gvar[size_t(y) * size_t(W) + size_t(i)] = s / ws;
          }
      });
      atrous_pass(acc, t, g, 1 << it, var.data(), var_next.data(),
                  [&](size_t p, size_t q, const Planes& a, const Planes& gg) {
                    const float lp = luminance(a.ch(0)[p], a.ch(1)[p], a.ch(2)[p]);
                    const float lq = luminance(a.ch(0)[q], a.ch(1)[q], a.ch(2)[q]);
                    const float wl = std::abs(lp - lq) / (sigma_l * std::sqrt(gvar[p]) + 1e-4f);
                    const float wz = dz.weight(gg, p, q, sigma_z);
                    const bool no_normal = gg.ch(6)[p] == 0 && gg.ch(7)[p] == 0 && gg.ch(8)[p] == 0;
                    const float wn = no_normal ? 1.0f
                                               : pow2k(std::max(0.0f, normal_dot(gg, p, q)),
                                                       7);  // ^sigma_n = ^128
                    return wn * std::exp(-wl - wz);
                  });
      std::swap(acc, t);
      std::swap(var, var_next);
      if (it == 0) first = acc;
    }
    history = Planes(W, H, 10);
    for (size_t p = 0; p < N; ++p) {
      for (int c = 0; c < 3; ++c) history.ch(c)[p] = first.ch(c)[p];
      history.ch(3)[p] = m1[p], history.ch(4)[p] = m2[p], history.ch(5)[p] = len[p];
      history.ch(6)[p] = g.ch(9)[p];
      for (int c = 0; c < 3; ++c) history.ch(7 + c)[p] = g.ch(6 + c)[p];
    }
    return remodulate(acc, g);
  }
};

}  // namespace

struct Denoiser::Impl {
  DenoiserOptions options;
  std::optional<denoise::NeuralWeights> weights;
  Planes state, inputs;
  denoise::Workspace workspace;
  bool profile = std::getenv("KESTREL_DENOISE_PROFILE") != nullptr;
  Svgf svgf;
};

Denoiser::Denoiser(const DenoiserOptions& options) : impl_(std::make_unique<Impl>()) {
  impl_->options = options;
  if (options.method == DenoiseMethod::neural)
    impl_->weights = denoise::NeuralWeights::load(
        options.weights.empty() ? default_denoiser_weights() : options.weights);
}
Denoiser::~Denoiser() = default;
Denoiser::Denoiser(Denoiser&&) noexcept = default;
Denoiser& Denoiser::operator=(Denoiser&&) noexcept = default;

void Denoiser::reset() {
  impl_->state = Planes();
  impl_->svgf = Svgf();
}

DenoiseMethod Denoiser::method() const {
  return impl_->options.method;
}
size_t Denoiser::parameter_count() const {
  return impl_->weights ? impl_->weights->parameters : 0;
}

FloatImage Denoiser::denoise(const DenoiseInput& input) {
  FloatImage out;
  denoise(input, out);
  return out;
}

void Denoiser::denoise(const DenoiseInput& input, FloatImage& out) {
  const int width = input.color ? input.color->width : 0,
            height = input.color ? input.color->height : 0;
  switch (impl_->options.method) {
    case DenoiseMethod::neural: {
      Planes& g = impl_->inputs;
      gather(input, 8, g);
      // The state is kept at the padded size of this sequence's frames; a size change restarts it.
      if (impl_->state.width != g.width || impl_->state.height != g.height) impl_->state = Planes();
      // Re-pad the state as the reference does: the previous output's edges replicated.
      else if (!impl_->state.data.empty())
        replicate_edges(impl_->state, width, height);
      denoise::StageTimes times;
      const Planes& result =
          denoise::run_network(*impl_->weights, g, impl_->state, impl_->options.recurrent,
                               impl_->workspace, impl_->profile ? &times : nullptr);
      if (impl_->profile)
        fmt::print(stderr,
                   "denoise stages (ms): prepare {:.1f}  features {:.1f}  cnn {:.1f}  temporal "
                   "{:.1f}  filter {:.1f}  output {:.1f}\n",
                   times.prepare, times.features, times.cnn, times.temporal, times.filter,
                   times.output);
      to_image(result, width, height, out);
      return;
    }
    case DenoiseMethod::svgf:
      to_image(impl_->svgf.run(gather(input, 1)), width, height, out);
      return;
    case DenoiseMethod::atrous:
      to_image(atrous_filter(gather(input, 1)), width, height, out);
      return;
  }
}

}  // namespace kestrel
