// kestrel::Denoiser: input checks and padding, the neural denoiser's state, and the
// dispatch to the non-neural baselines (svgf.h).
#include "kestrel/denoise.h"

#include <fmt/format.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <filesystem>

#include "core/parallel.h"
#include "denoise/kernels.h"
#include "denoise/neural.h"
#include "denoise/rae.h"
#include "denoise/svgf.h"
#include "kestrel/error.h"
#include "kestrel/trace.h"
#include "nn/conv.h"

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
    case DenoiseMethod::rae:
      return "rae";
  }
  return "?";
}

std::optional<DenoiseMethod> denoise_method_from_name(std::string_view name) {
  for (DenoiseMethod m :
       {DenoiseMethod::neural, DenoiseMethod::svgf, DenoiseMethod::atrous, DenoiseMethod::rae})
    if (name == denoise_method_name(m)) return m;
  return std::nullopt;
}

std::string default_denoiser_weights(DenoiseMethod method) {
  const char* file = method == DenoiseMethod::rae ? "denoiser_rae.kdw" : "denoiser.kdw";
  if (const char* dir = std::getenv("KESTREL_WEIGHTS_DIR"); dir && *dir)
    return std::string(dir) + "/" + file;
  return std::string(KESTREL_SOURCE_DIR) + "/weights/" + file;
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

// dst[x] = src[x * stride] with NaN and +-Inf set to 0, and negative values too if `colour`
// (-0 kept): on the bits, branch-free. kStride: the stride if known (0: `stride`).
template <int kStride>
void copy_clean(const float* src, float* dst, int n, int stride, bool colour) {
  const size_t st = kStride ? size_t(kStride) : size_t(stride);
  const uint32_t negative = colour ? 0x80000000u : 0u;
  for (int x = 0; x < n; ++x) {
    const uint32_t b = std::bit_cast<uint32_t>(src[size_t(x) * st]);
    const uint32_t keep = uint32_t((b & 0x7F800000u) != 0x7F800000u) &
                          uint32_t(((b & negative) == 0u) | ((b & 0x7FFFFFFFu) == 0u));
    dst[x] = std::bit_cast<float>(b & (0u - keep));
  }
}

// The inputs as padded planes (multiple of `align`, edge replicated): colour 0-2, albedo
// 3-5, normal 6-8, depth 9, roughness 10, motion 11-12; NaN/Inf to 0, negative colour to 0;
// absent images: albedo 1, normal 0, depth 1, roughness 0, motion 0. `p` is reused. Without
// `roughness` (SVGF-like does not read it) plane 10 is left as it is.
void gather(const DenoiseInput& in, int align, Planes& p, bool roughness = true) {
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
  p.image_width = c.width, p.image_height = c.height;
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
        for (int k = 0; k < s.count && (roughness || s.first != 10); ++k) {
          float* dst = p.ch(s.first + k) + row;
          if (!s.img) {
            std::fill(dst, dst + cw, s.fallback);
            continue;
          }
          const int stride = s.img->channels;
          const float* src =
              s.img->pixels.data() + size_t(y) * size_t(cw) * size_t(stride) + size_t(k);
          const bool colour = s.first == 0;
          // A constant stride lets the compiler vectorise the copy.
          using Copy = void (*)(const float*, float*, int, int, bool);
          static constexpr Copy copies[] = {copy_clean<0>, copy_clean<1>, copy_clean<2>,
                                            copy_clean<3>, copy_clean<4>};
          copies[stride <= 4 ? stride : 0](src, dst, cw, stride, colour);
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

}  // namespace

struct Denoiser::Impl {
  DenoiserOptions options;
  std::optional<denoise::NeuralWeights> weights;
  std::optional<denoise::Rae> rae;
  Planes state, inputs, output;
  denoise::Workspace workspace;
  bool profile = std::getenv("KESTREL_DENOISE_PROFILE") != nullptr;
  denoise::Svgf svgf;
};

Denoiser::Denoiser(const DenoiserOptions& options) : impl_(std::make_unique<Impl>()) {
  impl_->options = options;
  const std::string weights =
      options.weights.empty() ? default_denoiser_weights(options.method) : options.weights;
  if (options.method == DenoiseMethod::neural) {
    impl_->weights = denoise::NeuralWeights::load(weights);
    impl_->workspace.bf16 = options.bf16;
  } else if (options.method == DenoiseMethod::rae)
    impl_->rae.emplace(weights, options.bf16);
}
Denoiser::~Denoiser() = default;
Denoiser::Denoiser(Denoiser&&) noexcept = default;
Denoiser& Denoiser::operator=(Denoiser&&) noexcept = default;

void Denoiser::reset() {
  impl_->state = Planes();
  impl_->svgf.reset();
  if (impl_->rae) impl_->rae->reset();
}

DenoiseMethod Denoiser::method() const {
  return impl_->options.method;
}
size_t Denoiser::parameter_count() const {
  return impl_->weights ? impl_->weights->parameters : impl_->rae ? impl_->rae->parameters() : 0;
}
bool Denoiser::uses_bf16() const {
  if (impl_->rae) return impl_->rae->bf16();
  return impl_->weights && nn::conv_kernels(default_isa(), impl_->options.bf16).bf16;
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
    case DenoiseMethod::svgf: {
      gather(input, 1, impl_->inputs, /*roughness=*/false);
      denoise::SvgfTimes times;
      impl_->svgf.run_taking(impl_->inputs, out, impl_->profile ? &times : nullptr);
      if (impl_->profile)
        fmt::print(stderr,
                   "svgf stages (ms): temporal {:.1f}  variance {:.1f}  passes {:.1f}  output "
                   "{:.1f}\n",
                   times.temporal, times.variance, times.passes, times.output);
      return;
    }
    case DenoiseMethod::atrous:
      to_image(denoise::atrous_filter(gather(input, 1)), width, height, out);
      return;
    case DenoiseMethod::rae:
      gather(input, 1, impl_->inputs);
      if (!impl_->options.recurrent) impl_->rae->reset();
      impl_->rae->run(impl_->inputs, impl_->output);
      to_image(impl_->output, width, height, out);
      return;
  }
}

}  // namespace kestrel
