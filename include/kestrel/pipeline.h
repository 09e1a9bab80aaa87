// The real-time frame loop: per frame, update the scene (animation, TLAS), trace at the
// internal resolution with jitter (1 spp, NEE), denoise, upsample to the output resolution
// and tone-map; every stage timed, all on the caller's TBB arena. See docs/pipeline.md.
#pragma once
#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "kestrel/asset.h"
#include "kestrel/denoise.h"
#include "kestrel/render.h"
#include "kestrel/upscale.h"

namespace kestrel {

struct PipelineSettings {
  int width = 1280, height = 720;  ///< output resolution
  int factor = 2;                  ///< internal = output / factor: 1, 2 or 4
  bool denoise = true;
  DenoiseMethod denoiser = DenoiseMethod::neural;
  UpscaleMethod upscaler = UpscaleMethod::neural;  ///< unused at factor 1
  int spp = 1, max_depth = 4;
  /// RenderSettings::indirect_rate: 1, 0.5 or 0.25 of the pixels trace a first bounce.
  float indirect_rate = 1.0f;
  bool jitter = true;        ///< sub-pixel Halton jitter by frame (false: pixel centres)
  bool fixed_jitter = true;  ///< every sample of a frame at its jitter (what upsamplers expect)
  int threads = 0;           ///< the render's threads (RenderSettings::threads; 0 = all)
  float clamp = 16.0f;       ///< sample radiance clamp (0 = off): fireflies hurt a 1-spp loop
  float exposure = 0.0f;     ///< stops, for the tone map (added to the automatic exposure)
  /// Automatic exposure: the tone map's exposure follows the log-average luminance of the
  /// output (key 0.18, Reinhard et al. 2002), 10 % of the way per frame (the first frame
  /// jumps), clamped to +-16 stops. PipelineFrame::exposure says what was used.
  bool auto_exposure = false;
  LightSampling light_sampling = LightSampling::power;  ///< NEE's choice of a local light
  DirectLighting direct = DirectLighting::nee;          ///< the first hit's direct light
  /// Choose by the scene instead: with >= 64 lights, ReSTIR DI (biased) over the light tree,
  /// else the two fields above (`kestrel run` / `view`'s default, `--direct auto`).
  bool auto_lighting = false;
  /// The world-space radiance cache (RenderSettings::radiance_cache; biased): most paths stop
  /// at their first bounce's surface. `kestrel run` / `view` turn it on (--radiance-cache).
  bool radiance_cache = false;
  std::string sun;   ///< "" or Sun::parse's AZIMUTH,ELEVATION[,INTENSITY] (make_lighting)
  bool sky = false;  ///< the physical sky (make_lighting)
  /// > 0: hold this frame time — when over 1.15x it, halve indirect_rate down to 0.25, then
  /// double the factor up to 4; when under it, the reverse (the rate back under 0.7x, a finer
  /// factor under 0.3x at the full rate)
  double target_ms = 0;
  uint64_t seed = 0;
};

/// Milliseconds of one frame's stages.
struct PipelineTimes {
  double update = 0, render = 0, denoise = 0, upscale = 0, tonemap = 0, total = 0;
};

/// What the loop shows. The images are reused from frame to frame.
struct PipelineFrame {
  FloatImage noisy;           ///< the internal-resolution render (colour)
  Frame render;               ///< that render: every AOV (its colour also in noisy) and stats
  FloatImage denoised;        ///< after the denoiser (= noisy without one)
  FloatImage upscaled;        ///< the output resolution, linear
  std::vector<uint8_t> rgb8;  ///< upscaled, tone-mapped sRGB, width x height x 3
  int width = 0, height = 0, internal_width = 0, internal_height = 0, factor = 1;
  uint32_t index = 0;  ///< frames since the start (the Halton jitter's index)
  float exposure = 0;  ///< stops the tone map applied (settings + automatic)
  PipelineTimes times;
  RenderStats stats;
};

/// How a frame is rendered (default: Renderer::render). A distributed render returns the
/// frame on one process and an empty Frame (width 0) on the others, whose pipelines then
/// skip the stages after the render.
using PipelineRenderFn = std::function<Frame(Renderer&, const Camera&, const RenderSettings&,
                                             const std::optional<Camera>& prev_camera)>;

/// The one frame loop of kestrel: `run`, `view`, `render-sequence` and the evaluation
/// programs all go through it.
class Pipeline {
 public:
  /// Loads a scene (Asset::load: OBJ, glTF/GLB with its animation, builtin:NAME) and builds
  /// its acceleration structures. environment: as Environment::parse ("" = the scene's
  /// default). Throws Error naming the file or the bad setting.
  Pipeline(const std::string& scene, const PipelineSettings& settings,
           const std::string& environment = "");
  /// A loaded asset, owned from now on.
  Pipeline(Asset asset, const PipelineSettings& settings, const std::string& environment = "");
  ~Pipeline();
  Pipeline(Pipeline&&) noexcept;
  Pipeline& operator=(Pipeline&&) noexcept;

  /// Runs one frame at scene time `time` (seconds; animations) seen by `camera`; the
  /// previous frame's camera drives the motion vectors.
  const PipelineFrame& frame(const Camera& camera, double time);
  /// Progressive reference: adds one full-resolution sample per pixel to a running mean
  /// (restarted when the camera or time changes) and returns it tone-mapped in rgb8.
  const PipelineFrame& accumulate(const Camera& camera, double time);
  /// Samples per pixel in the progressive reference so far.
  int accumulated() const;

  /// New settings; resets the temporal history when the resolution or methods change.
  void set_settings(const PipelineSettings& settings);
  const PipelineSettings& settings() const;
  /// Forgets the history (denoiser, upsampler, previous camera).
  void reset();
  /// Replaces how frames are rendered (see PipelineRenderFn).
  void set_render_function(PipelineRenderFn render);
  const Asset& asset() const;
  const Renderer& renderer() const;
  /// The direct lighting and light sampling the frames use (auto_lighting resolved).
  DirectLighting direct_lighting() const;
  LightSampling light_sampling() const;
  /// Bounds of the scene, the source's name, whether it animates (glTF animation).
  Bounds3 bounds() const;
  const std::string& source() const;
  double animation_duration() const;
  size_t triangle_count() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace kestrel
