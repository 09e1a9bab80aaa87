// The radiance cache (RenderSettings::radiance_cache) against full paths, one frame as the
// real-time loop renders it: after --frames frames of history (a still camera, then a camera
// turning --turn degrees per frame), the frame's render time, rays and relMSE against a
// converged reference without the cache; full paths at 1 spp and at the samples per pixel
// that fit in the cached frame's time (a time limit). The cache's bias alone: the mean of
// --mean-frames further cached frames against the reference (noise averaged away).
#include <fmt/format.h>
#include <CLI/CLI.hpp>

#include <cmath>
#include <string>
#include <vector>

#include "image_metrics.h"
#include "kestrel/kestrel.h"
#include "kestrel/pipeline.h"

using namespace kestrel;
using bench::median;
using bench::relmse;

namespace {

// The camera turned about the vertical axis through its eye by `degrees`.
Camera turned(Camera c, float degrees) {
  const float a = degrees * 3.14159265f / 180.0f, ca = std::cos(a), sa = std::sin(a);
  const Vec3 d = c.target - c.eye;
  c.target = c.eye + Vec3{ca * d.x + sa * d.z, d.y, -sa * d.x + ca * d.z};
  return c;
}

double mean_luminance(const FloatImage& img) {
  double sum = 0;
  const size_t n = size_t(img.width) * size_t(img.height);
  for (size_t p = 0; p < n; ++p) {
    const float* c = &img.pixels[3 * p];
    sum += 0.2126 * c[0] + 0.7152 * c[1] + 0.0722 * c[2];
  }
  return n ? sum / double(n) : 0.0;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"kestrel radiance-cache benchmark"};
  std::string scene = "../shared/scenes/dabrovic_sponza/sponza.obj", view = "inside",
              res = "320x180", env, sun, png;
  bool sky = false, quick = false;
  int ref_spp = 1024, runs = 3, threads = 1, depth = 4, frames = 16, mean_frames = 32;
  float turn = 1.0f;
  app.add_option("--scene", scene, "Scene")->capture_default_str();
  app.add_option("--view", view, "View")->capture_default_str();
  app.add_option("--res", res, "Resolution")->capture_default_str();
  app.add_option("--env", env, "Environment (default: the scene's suggestion, else overcast)");
  app.add_option("--sun", sun, "Sun AZ,EL[,I] (default: the scene's suggestion)");
  app.add_flag("--sky", sky, "The physical sky");
  app.add_option("--ref-spp", ref_spp, "Reference passes (no cache)")->capture_default_str();
  app.add_option("--runs", runs, "Runs per case (median; seeds differ)")->capture_default_str();
  app.add_option("--threads", threads, "Threads")->capture_default_str();
  app.add_option("--max-depth", depth, "Path depth")->capture_default_str();
  app.add_option("--frames", frames, "Frames of history before the measured one")
      ->capture_default_str();
  app.add_option("--mean-frames", mean_frames, "Cached frames averaged for the bias")
      ->capture_default_str();
  app.add_option("--turn", turn, "Degrees per frame of the turning camera")->capture_default_str();
  app.add_option("--png", png,
                 "Write the still camera's first run side by side: full paths at 1 spp, the "
                 "cached frame, the reference");
  app.add_flag("--quick", quick, "Tiny run (CI)");
  CLI11_PARSE(app, argc, argv);
  try {
    if (quick) res = "64x36", ref_spp = 32, runs = 1, frames = 3, mean_frames = 2;
    int w = 0, h = 0;
    if (std::sscanf(res.c_str(), "%dx%d", &w, &h) != 2 || w <= 0 || h <= 0)
      throw Error(ErrorCode::invalid_argument, "--res WxH");
    ThreadLimit limit(threads);
    Asset asset = Asset::load(scene);
    if (env.empty() && sun.empty() && !sky)
      if (const auto l = suggested_lighting(scene)) env = l->env, sun = l->sun, sky = l->sky;
    const auto view_cam = find_view(asset, view);
    if (!view_cam)
      throw Error(ErrorCode::invalid_argument, fmt::format("{}: no view '{}'", scene, view));
    RenderSettings s;
    s.width = w, s.height = h, s.max_depth = depth, s.seed = 7;
    fmt::print("scene {}, {}x{}, depth {}, {} thread(s), lighting: env '{}' sun '{}'{}\n", scene, w,
               h, depth, threads, env, sun, sky ? " sky" : "");
    fmt::print(
        "relMSE of one frame after {} frames of history against a {}-spp reference without the "
        "cache; median of {} runs\n\n",
        frames, ref_spp, runs);
    fmt::print(
        "| camera | method | ms / frame | rays / pixel | spp | relMSE | relMSE x ms (÷ full "
        "paths') | relMSE ÷ full paths' at >= equal time | PSNR dB (tone-mapped) |\n"
        "|---|---|---:|---:|---:|---:|---:|---:|---:|\n");
    for (int moving = 0; moving < 2; ++moving) {
      const Camera last = moving ? turned(*view_cam, turn * float(frames)) : *view_cam;
      Renderer ref_r(asset.scene(), make_lighting(env, sun, sky));
      RenderSettings rs = s;
      rs.spp = ref_spp;
      const Frame ref = ref_r.render(last, rs);
      std::vector<double> cached_ms, cached_rays, cached_rel, full_rel, eq_rel, eq_spp, full_ms,
          full_rays, cached_psnr, full_psnr;
      std::vector<double> bias, full_mean, lum_ratio;
      for (int k = 0; k < runs; ++k) {
        Renderer r(asset.scene(), make_lighting(env, sun, sky));
        RenderSettings cs = s;
        cs.radiance_cache = true, cs.seed = 100 + uint64_t(k);
        Frame f;
        for (int i = 0; i <= frames; ++i) {
          cs.frame = uint32_t(i);
          const Camera c = moving ? turned(*view_cam, turn * float(i)) : *view_cam;
          std::optional<Camera> prev;
          if (i > 0) prev = moving ? turned(*view_cam, turn * float(i - 1)) : *view_cam;
          f = r.render(c, cs, prev);
        }
        cached_ms.push_back(f.stats.ms);
        cached_rays.push_back(double(f.stats.rays()) / (double(w) * h));
        cached_rel.push_back(relmse(f[Aov::color], ref[Aov::color]));
        const std::vector<float> ref_tm = bench::tonemapped(ref[Aov::color]);
        cached_psnr.push_back(bench::psnr(bench::tonemapped(f[Aov::color]), ref_tm));
        if (!moving && mean_frames > 0) {  // the mean of further frames: the cache's bias
          FloatImage sum = f[Aov::color];
          for (int i = 1; i <= mean_frames; ++i) {
            cs.frame = uint32_t(frames + i);
            const Frame g = r.render(*view_cam, cs, *view_cam);
            for (size_t p = 0; p < sum.pixels.size(); ++p) sum.pixels[p] += g[Aov::color].pixels[p];
          }
          for (float& v : sum.pixels) v /= float(mean_frames + 1);
          bias.push_back(relmse(sum, ref[Aov::color]));
          lum_ratio.push_back(mean_luminance(sum) / mean_luminance(ref[Aov::color]));
        }
        Renderer full(asset.scene(), make_lighting(env, sun, sky));
        RenderSettings fs = s;
        fs.seed = 100 + uint64_t(k), fs.frame = uint32_t(frames);
        const Frame one = full.render(last, fs);
        if (!png.empty() && !moving && k == 0)
          bench::write_crop_png(png, {&one[Aov::color], &f[Aov::color], &ref[Aov::color]}, 0, 0, w,
                                h);
        full_rel.push_back(relmse(one[Aov::color], ref[Aov::color]));
        full_psnr.push_back(bench::psnr(bench::tonemapped(one[Aov::color]), ref_tm));
        full_ms.push_back(one.stats.ms);
        full_rays.push_back(double(one.stats.rays()) / (double(w) * h));
        fs.spp = 1 << 16, fs.time_limit_s = f.stats.ms / 1000.0;
        const Frame eq = full.render(last, fs);
        eq_rel.push_back(relmse(eq[Aov::color], ref[Aov::color]));
        eq_spp.push_back(eq.stats.passes);
        if (!moving && mean_frames > 0) {  // full paths with as many samples as the mean
          fs.spp = mean_frames + 1, fs.time_limit_s = 0;
          full_mean.push_back(relmse(full.render(last, fs)[Aov::color], ref[Aov::color]));
        }
      }
      const char* cam = moving ? "turning" : "still";
      const double cr = median(cached_rel), er = median(eq_rel);
      const double full_eff = median(full_rel) * median(full_ms),
                   cached_eff = cr * median(cached_ms);
      fmt::print(
          "| {} | full paths, 1 spp | {:.1f} | {:.2f} | 1 | {:.4f} | {:.3g} (1) | | {:.2f} |\n",
          cam, median(full_ms), median(full_rays), median(full_rel), full_eff, median(full_psnr));
      fmt::print("| {} | full paths, time of the cached frame | | | {:.0f} | {:.4f} | | 1 |\n", cam,
                 median(eq_spp), er);
      fmt::print(
          "| {} | radiance cache, 1 spp | {:.1f} | {:.2f} | 1 | {:.4f} | {:.3g} ({:.3f}) | {:.3f} "
          "| {:.2f} |\n",
          cam, median(cached_ms), median(cached_rays), cr, cached_eff, cached_eff / full_eff,
          cr / er, median(cached_psnr));
      // What the loop shows: the same frames through the neural denoiser (kestrel::Pipeline at
      // factor 1, its own settings otherwise), cache on and off, against the same reference.
      for (const bool cache : {true, false}) {
        PipelineSettings ps;
        ps.width = w, ps.height = h, ps.factor = 1, ps.max_depth = depth, ps.seed = 100;
        ps.sun = sun, ps.sky = sky, ps.radiance_cache = cache;
        Pipeline loop(scene, ps, env);
        std::vector<double> psnr, ms;
        for (int i = 0; i <= frames; ++i) {
          const Camera c = moving ? turned(*view_cam, turn * float(i)) : *view_cam;
          const PipelineFrame& out = loop.frame(c, 0.0);
          if (i + 4 > frames) ms.push_back(out.times.render + out.times.denoise);
          if (i == frames)
            psnr.push_back(
                bench::psnr(bench::tonemapped(out.denoised), bench::tonemapped(ref[Aov::color])));
        }
        fmt::print(
            "| {} | loop (neural denoiser), cache {} | {:.1f} (render + denoise) | | 1 | | | | "
            "{:.2f} |\n",
            cam, cache ? "on" : "off", median(ms), psnr[0]);
      }
      if (!bias.empty()) {
        fmt::print("| {} | full paths, {} spp | | | {} | {:.4f} | |\n", cam, mean_frames + 1,
                   mean_frames + 1, median(full_mean));
        fmt::print(
            "| {} | radiance cache, mean of {} frames | | | {} | {:.4f} | (mean luminance {:.3f} "
            "x the reference's) |\n",
            cam, mean_frames + 1, mean_frames + 1, median(bias), median(lum_ratio));
      }
    }
  } catch (const Error& e) {
    fmt::print(stderr, "error: {}\n", e.what());
    return 1;
  }
  return 0;
}
