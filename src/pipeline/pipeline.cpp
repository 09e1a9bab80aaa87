// The real-time frame loop (kestrel/pipeline.h): scene update, 1-spp render at the internal
// resolution, denoiser, upsampler, tone map; each stage timed.
#include "kestrel/pipeline.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <string>

#include "core/timer.h"
#include "kestrel/error.h"

namespace kestrel {

namespace {

void check(const PipelineSettings& s) {
  if (s.width <= 0 || s.height <= 0 || s.width > 16384 || s.height > 16384)
    throw Error(ErrorCode::invalid_argument,
                fmt::format("pipeline: output {}x{} is out of range", s.width, s.height));
  if (s.factor != 1 && s.factor != 2 && s.factor != 4)
    throw Error(ErrorCode::invalid_argument,
                fmt::format("pipeline: factor must be 1, 2 or 4, got {}", s.factor));
  if (s.width % s.factor || s.height % s.factor)
    throw Error(ErrorCode::invalid_argument,
                fmt::format("pipeline: output {}x{} is not divisible by the factor {}", s.width,
                            s.height, s.factor));
  if (s.spp <= 0 || s.max_depth <= 0 || !(s.clamp >= 0) || !std::isfinite(s.exposure) ||
      !(s.target_ms >= 0))
    throw Error(ErrorCode::invalid_argument,
                "pipeline: spp and max depth must be positive, clamp and target time >= 0");
  if (s.indirect_rate != 1.0f && s.indirect_rate != 0.5f && s.indirect_rate != 0.25f)
    throw Error(
        ErrorCode::invalid_argument,
        fmt::format("pipeline: indirect rate must be 1, 0.5 or 0.25, got {}", s.indirect_rate));
}

}  // namespace

struct Pipeline::Impl {
  PipelineSettings settings;
  Asset asset;
  std::unique_ptr<Renderer> renderer;
  PipelineRenderFn render_fn;
  std::unique_ptr<Denoiser> denoiser;
  std::unique_ptr<Upscaler> upscaler;
  std::optional<Camera> prev_camera;
  double last_time = -1;
  float auto_stops = 0;
  bool auto_started = false;

  // Stops that bring the log-average luminance (every 4th pixel of every 4th row) to 0.18,
  // moved 10 % of the way from the previous frame's (the first frame: all the way).
  float auto_exposure(const FloatImage& img) {
    double sum = 0;
    size_t n = 0;
    for (int y = 0; y < img.height; y += 4)
      for (int x = 0; x < img.width; x += 4) {
        const float* p = img.at(x, y);
        const float l = 0.2126f * p[0] + 0.7152f * p[1] + 0.0722f * p[2];
        if (!std::isfinite(l)) continue;
        sum += std::log(1e-4 + std::max(0.0f, l));
        ++n;
      }
    if (n == 0) return auto_stops;
    const float target =
        std::clamp(float(std::log2(0.18 / std::exp(sum / double(n)))), -16.0f, 16.0f);
    auto_stops = auto_started ? auto_stops + 0.1f * (target - auto_stops) : target;
    auto_started = true;
    return auto_stops;
  }
  PipelineFrame out;
  // Progressive reference.
  std::vector<double> sum;
  int samples = 0;
  std::optional<Camera> acc_camera;
  double acc_time = 0;

  void make_filters() {
    denoiser.reset(), upscaler.reset();
    if (settings.denoise) {
      DenoiserOptions o;
      o.method = settings.denoiser;
      denoiser = std::make_unique<Denoiser>(o);
    }
    if (settings.factor > 1) {
      UpscalerOptions o;
      o.method = settings.upscaler, o.factor = settings.factor;
      upscaler = std::make_unique<Upscaler>(o);
    }
    prev_camera.reset();
  }

  explicit Impl(Asset a) : asset(std::move(a)) {}

  // Poses the scene at `time` (BLAS refits / rebuilds, TLAS); the renderer sees the commit.
  void update(double time) {
    if (time == last_time) return;
    asset.update(time);
    last_time = time;
  }

  // auto_lighting: many lights (ReSTIR's and the light tree's case) or the settings' choice.
  bool many_lights() const { return settings.auto_lighting && renderer->light_count() >= 64; }
  DirectLighting direct() const { return many_lights() ? DirectLighting::restir : settings.direct; }
  LightSampling light_sampling() const {
    return many_lights() ? LightSampling::tree : settings.light_sampling;
  }

  RenderSettings render_settings(int w, int h, uint32_t frame) const {
    RenderSettings rs;
    rs.width = w, rs.height = h, rs.spp = settings.spp, rs.seed = settings.seed, rs.frame = frame;
    rs.max_depth = settings.max_depth, rs.clamp = settings.clamp,
    rs.fixed_jitter = settings.fixed_jitter;
    rs.jitter = settings.jitter, rs.threads = settings.threads;
    rs.light_sampling = light_sampling(), rs.direct = direct();
    rs.radiance_cache = settings.radiance_cache;
    rs.indirect_rate = settings.indirect_rate;
    return rs;
  }
};

Pipeline::Pipeline(const std::string& scene, const PipelineSettings& settings,
                   const std::string& environment)
    : Pipeline((check(settings), Asset::load(scene)), settings, environment) {}

Pipeline::Pipeline(Asset asset, const PipelineSettings& settings, const std::string& environment)
    : impl_(std::make_unique<Impl>(std::move(asset))) {
  check(settings);
  Impl& m = *impl_;
  m.settings = settings;
  m.renderer = std::make_unique<Renderer>(m.asset.scene(),
                                          make_lighting(environment, settings.sun, settings.sky));
  m.last_time = 0;  // loaded (posed) at t = 0
  m.make_filters();
}

Pipeline::~Pipeline() = default;
Pipeline::Pipeline(Pipeline&&) noexcept = default;
Pipeline& Pipeline::operator=(Pipeline&&) noexcept = default;

void Pipeline::set_settings(const PipelineSettings& s) {
  check(s);
  const PipelineSettings old = impl_->settings;
  impl_->settings = s;
  if (s.factor != old.factor || s.width != old.width || s.height != old.height ||
      s.denoise != old.denoise || s.denoiser != old.denoiser || s.upscaler != old.upscaler)
    impl_->make_filters();
  if (s.width != old.width || s.height != old.height || s.max_depth != old.max_depth ||
      s.clamp != old.clamp)
    impl_->samples = 0;
}

const PipelineSettings& Pipeline::settings() const {
  return impl_->settings;
}
void Pipeline::reset() {
  impl_->make_filters();
  impl_->auto_started = false;
  impl_->samples = 0;
}
Bounds3 Pipeline::bounds() const {
  return impl_->renderer->bounds();
}
const std::string& Pipeline::source() const {
  return impl_->asset.source();
}
double Pipeline::animation_duration() const {
  return impl_->asset.duration();
}
size_t Pipeline::triangle_count() const {
  return impl_->asset.triangle_count();
}
void Pipeline::set_render_function(PipelineRenderFn render) {
  impl_->render_fn = std::move(render);
}
const Asset& Pipeline::asset() const {
  return impl_->asset;
}
const Renderer& Pipeline::renderer() const {
  return *impl_->renderer;
}
DirectLighting Pipeline::direct_lighting() const {
  return impl_->direct();
}
LightSampling Pipeline::light_sampling() const {
  return impl_->light_sampling();
}
int Pipeline::accumulated() const {
  return impl_->samples;
}

const PipelineFrame& Pipeline::frame(const Camera& camera, double time) {
  Impl& m = *impl_;
  PipelineFrame& o = m.out;
  const PipelineSettings& s = m.settings;
  const Timer clock;
  m.update(time);
  const double t1 = clock.ms();
  const int iw = s.width / s.factor, ih = s.height / s.factor;
  const RenderSettings rs = m.render_settings(iw, ih, o.index);
  // The render lands in o.render, whose images keep their storage from frame to frame.
  Frame& f = o.render;
  if (m.render_fn)
    f = m.render_fn(*m.renderer, camera, rs, m.prev_camera);
  else
    m.renderer->render(camera, rs, m.prev_camera, f);
  m.prev_camera = camera;
  const double t2 = clock.ms();
  if (f.width == 0) {  // a worker of a distributed render: the frame is elsewhere
    o.times = {t1, t2 - t1, 0, 0, 0, t2};
    ++o.index;
    return o;
  }
  o.noisy = f[Aov::color];
  if (m.denoiser)
    m.denoiser->denoise({&o.noisy, &f[Aov::albedo], &f[Aov::normal], &f[Aov::depth],
                         &f[Aov::roughness], &f[Aov::motion]},
                        o.denoised);
  else
    o.denoised = o.noisy;
  const double t3 = clock.ms();
  if (m.upscaler)
    m.upscaler->upscale({&o.denoised, &f[Aov::depth], &f[Aov::motion], f.jitter_x, f.jitter_y},
                        o.upscaled);
  else
    o.upscaled = o.denoised;
  const double t4 = clock.ms();
  o.exposure = s.exposure + (s.auto_exposure ? m.auto_exposure(o.upscaled) : 0.0f);
  tonemap_srgb8(o.upscaled, o.exposure, o.rgb8);
  const double t5 = clock.ms(), t0 = 0;
  o.width = s.width, o.height = s.height, o.internal_width = iw, o.internal_height = ih,
  o.factor = s.factor;
  o.times = {t1 - t0, t2 - t1, t3 - t2, t4 - t3, t5 - t4, t5 - t0};
  o.stats = f.stats;
  ++o.index;
  // Hold the target frame time. When slow, fewer first bounces before a coarser factor (on
  // held-out clips a quarter of the first bounces cost ~0.5 dB, a factor of 4 instead of 2
  // ~2 dB); when well under it, the reverse: the full indirect rate back first (each step
  // costs ~1.3x: under 0.7x the target), then a finer factor (4x the pixels: under 0.3x).
  if (s.target_ms > 0) {
    PipelineSettings next = s;
    const double t = o.times.total, target = s.target_ms;
    const auto fits = [&](int f) { return s.width % f == 0 && s.height % f == 0; };
    if (t > 1.15 * target) {
      if (s.indirect_rate > 0.25f)
        next.indirect_rate = s.indirect_rate * 0.5f;
      else if (s.factor < 4 && fits(s.factor * 2))
        next.factor = s.factor * 2;
    } else if (s.indirect_rate < 1.0f) {
      if (t < 0.7 * target) next.indirect_rate = s.indirect_rate * 2.0f;
    } else if (t < 0.3 * target && s.factor > 1 && fits(s.factor / 2)) {
      next.factor = s.factor / 2;
    }
    if (next.factor != s.factor || next.indirect_rate != s.indirect_rate) set_settings(next);
  }
  return o;
}

const PipelineFrame& Pipeline::accumulate(const Camera& camera, double time) {
  Impl& m = *impl_;
  PipelineFrame& o = m.out;
  const PipelineSettings& s = m.settings;
  if (!m.acc_camera || *m.acc_camera != camera || m.acc_time != time ||
      m.sum.size() != size_t(s.width) * size_t(s.height) * 3)
    m.samples = 0;
  const Timer clock;
  m.update(time);
  const double t1 = clock.ms();
  RenderSettings rs = m.render_settings(s.width, s.height, uint32_t(m.samples));
  rs.fixed_jitter = false;  // antialiased: a new jitter every sample
  rs.seed = s.seed + 1000003;
  rs.direct = DirectLighting::nee;  // the reference: unbiased, no reuse between samples
  rs.radiance_cache = false;
  rs.indirect_rate = 1.0f;  // every pixel's bounce in every sample (the loop's budget is not its)
  const Frame f = m.renderer->render(camera, rs);
  const double t2 = clock.ms();
  if (m.samples == 0) m.sum.assign(size_t(s.width) * size_t(s.height) * 3, 0.0);
  const FloatImage& c = f[Aov::color];
  for (size_t i = 0; i < m.sum.size(); ++i)
    m.sum[i] += std::isfinite(c.pixels[i]) ? double(c.pixels[i]) : 0.0;
  ++m.samples;
  m.acc_camera = camera, m.acc_time = time;
  if (o.upscaled.width != s.width || o.upscaled.height != s.height || o.upscaled.channels != 3)
    o.upscaled = FloatImage(s.width, s.height, 3);
  for (size_t i = 0; i < m.sum.size(); ++i) o.upscaled.pixels[i] = float(m.sum[i] / m.samples);
  o.rgb8 = tonemap_srgb8(o.upscaled, s.exposure);
  const double t3 = clock.ms(), t0 = 0;
  o.width = s.width, o.height = s.height, o.internal_width = s.width, o.internal_height = s.height,
  o.factor = 1;
  o.times = {t1 - t0, t2 - t1, 0, 0, t3 - t2, t3 - t0};
  o.stats = f.stats;
  m.prev_camera.reset();  // the real-time history is stale after a rest
  return o;
}

}  // namespace kestrel
