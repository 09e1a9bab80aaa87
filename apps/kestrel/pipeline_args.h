// Options shared by `kestrel run` and `kestrel view`: the scene and the pipeline's settings.
#pragma once
#include <fmt/format.h>
#include <CLI/CLI.hpp>

#include <memory>
#include <string>

#include "commands.h"
#include "kestrel/asset.h"
#include "kestrel/error.h"
#include "kestrel/parallel.h"
#include "kestrel/pipeline.h"
#include "kestrel/render.h"

namespace kestrel::cli {

struct PipelineArgs {
  std::string scene = "builtin:cornell_box", res = "1280x720", internal, env, denoise = "neural",
              upscale = "neural", sun, lights, light_sampling = "power", direct = "auto",
              radiance_cache = "on";
  bool sky = false, auto_exposure = false;
  int factor = 2, spp = 1, max_depth = 4, threads = 0;
  float clamp = 16, exposure = 0, indirect_rate = 0.5f;
  double target_ms = 0;
  uint64_t seed = 0;
  std::shared_ptr<ThreadLimit> limit;

  void add_to(CLI::App& cmd) {
    cmd.add_option("scene", scene, "Scene file (OBJ, glTF, GLB) or builtin:NAME")
        ->capture_default_str();
    cmd.add_option("--res", res, "Output resolution WxH")->capture_default_str();
    cmd.add_option("--internal", internal,
                   "Internal (render) resolution WxH: output / 1, 2 or 4 (overrides --factor)");
    cmd.add_option("--factor", factor, "Output / internal resolution: 1, 2 or 4")
        ->capture_default_str();
    cmd.add_option("--denoise", denoise, "neural | svgf | atrous | rae | none")
        ->capture_default_str();
    cmd.add_option("--upscale", upscale, upscale_method_list(" | "))->capture_default_str();
    cmd.add_option("--spp", spp, "Samples per pixel per frame")
        ->capture_default_str()
        ->check(CLI::Range(1, 1 << 16));
    cmd.add_option("--max-depth", max_depth, "Path vertices after the camera")
        ->capture_default_str()
        ->check(CLI::Range(1, 1024));
    cmd.add_option("--clamp", clamp, "Sample radiance clamp (0 = off)")->capture_default_str();
    cmd.add_option("--indirect-rate", indirect_rate,
                   "Share of pixels that trace a first bounce each frame: 1 | 0.5 (a "
                   "checkerboard; the loop's default, for its frame budget) | 0.25; the others "
                   "keep their direct light (unbiased, noisier)")
        ->capture_default_str();
    cmd.add_option("--env", env, "Environment: none | sky | constant:R,G,B | image file");
    cmd.add_option("--exposure", exposure, "Tone-map exposure, stops")->capture_default_str();
    cmd.add_option(
        "--sun", sun,
        "A sun: AZIMUTH,ELEVATION[,INTENSITY] (degrees from north (-Z) towards east (+X); "
        "irradiance, default 10); with the physical sky unless --env");
    cmd.add_flag(
        "--sky", sky,
        "The physical sky (Preetham) for the sun (default sun: azimuth 135, elevation 45)");
    cmd.add_option("--lights", lights,
                   "A lights file (JSON: point / spot / directional lights, docs/renderer.md) "
                   "added to the scene's");
    cmd.add_option("--light-sampling", light_sampling,
                   "How NEE picks a local light: power | tree (a light tree: many lights)")
        ->capture_default_str();
    cmd.add_option("--direct", direct,
                   "Direct light at the first hit: auto (restir with the light tree for >= 64 "
                   "lights, else nee) | nee | restir (ReSTIR DI, biased) | restir-unbiased")
        ->capture_default_str();
    cmd.add_option("--radiance-cache", radiance_cache,
                   "on | off: paths stop at their first bounce's surface and take a world-space "
                   "cache's radiance there (biased; fewer rays per frame)")
        ->capture_default_str();
    cmd.add_flag("--auto-exposure", auto_exposure,
                 "Exposure follows the image's log-average luminance (key 0.18, smoothed)");
    cmd.add_option("--target-ms", target_ms,
                   "Hold this frame time (0 = fixed): fewer first bounces (--indirect-rate down "
                   "to 0.25) before a coarser factor (up to 4), and back");
    cmd.add_option("--seed", seed, "Random seed")->capture_default_str();
    cmd.add_option("--threads", threads, "Worker threads (0 = all)")
        ->capture_default_str()
        ->check(CLI::Range(0, 1024));
  }

  // The scene (its warnings printed) with the --lights file's lights added, as a pipeline.
  std::unique_ptr<Pipeline> pipeline(const PipelineSettings& s) const {
    Asset asset = load_asset_reporting(scene);
    if (!lights.empty()) asset.add_lights(load_lights(lights));
    return std::make_unique<Pipeline>(std::move(asset), s, env);
  }

  PipelineSettings settings() {
    if (threads > 0) limit = std::make_shared<ThreadLimit>(threads);
    // No lighting flag: the scene's views file may suggest one (Sponza: the sun).
    if (env.empty() && sun.empty() && !sky)
      if (const auto l = suggested_lighting(scene)) {
        env = l->env, sun = l->sun, sky = l->sky;
        fmt::print("lighting {}{}{} (the scene's views file; --env sky: the overcast sky)\n",
                   l->sun.empty() ? "" : "sun " + l->sun, l->env.empty() ? "" : " env " + l->env,
                   l->sky ? " sky" : "");
      }
    PipelineSettings s;
    parse_resolution(res, s.width, s.height);
    s.factor = factor;
    if (!internal.empty()) {
      int iw = 0, ih = 0;
      parse_resolution(internal, iw, ih);
      if (s.width % iw || s.height % ih || s.width / iw != s.height / ih)
        throw Error(
            ErrorCode::invalid_argument,
            fmt::format(
                "--internal {}: the output {} must be 1, 2 or 4 times it in both dimensions",
                internal, res));
      s.factor = s.width / iw;
    }
    s.denoise = denoise != "none";
    if (s.denoise) {
      const auto m = denoise_method_from_name(denoise);
      if (!m)
        throw Error(ErrorCode::invalid_argument,
                    fmt::format("--denoise '{}': expected neural, svgf, atrous or none", denoise));
      s.denoiser = *m;
    }
    const auto u = upscale_method_from_name(upscale);
    if (!u)
      throw Error(ErrorCode::invalid_argument, fmt::format("--upscale '{}': expected one of {}",
                                                           upscale, upscale_method_list()));
    s.upscaler = *u;
    s.spp = spp, s.max_depth = max_depth, s.clamp = clamp, s.exposure = exposure,
    s.indirect_rate = indirect_rate, s.target_ms = target_ms, s.seed = seed;
    s.sun = sun, s.sky = sky, s.auto_exposure = auto_exposure;
    if (light_sampling == "tree")
      s.light_sampling = LightSampling::tree;
    else if (light_sampling != "power")
      throw Error(ErrorCode::invalid_argument,
                  fmt::format("--light-sampling '{}': expected power or tree", light_sampling));
    s.auto_lighting = direct == "auto";
    const auto d = direct_lighting_from_name(s.auto_lighting ? "nee" : direct);
    if (!d)
      throw Error(
          ErrorCode::invalid_argument,
          fmt::format("--direct '{}': expected auto, nee, restir or restir-unbiased", direct));
    s.direct = *d;
    if (radiance_cache != "on" && radiance_cache != "off")
      throw Error(ErrorCode::invalid_argument,
                  fmt::format("--radiance-cache '{}': expected on or off", radiance_cache));
    s.radiance_cache = radiance_cache == "on";
    return s;
  }
};

}  // namespace kestrel::cli
