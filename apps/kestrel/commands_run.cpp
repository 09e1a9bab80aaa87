// `kestrel run`: the real-time pipeline headless along a camera path: frames (PNG, optional
// EXR) and a per-stage timing table (median, p95).
#include <fmt/format.h>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <memory>
#include <vector>

#include "commands.h"
#include "core/file_io.h"
#include "kestrel/error.h"
#include "kestrel/io.h"
#include "kestrel/pipeline.h"
#include "pipeline_args.h"

namespace kestrel::cli {

namespace {

struct RunArgs {
  PipelineArgs p;
  std::string path, view, out;
  int frames = 30;
  bool exr = false, no_png = false, quiet = false;
};

double percentile(std::vector<double> v, double q) {
  std::sort(v.begin(), v.end());
  const size_t i = std::min(v.size() - 1, size_t(q * double(v.size() - 1) + 0.5));
  return v[i];
}

void run(RunArgs& a) {
  if (a.frames <= 0)
    throw Error(ErrorCode::invalid_argument,
                fmt::format("run: --frames must be positive, got {}", a.frames));
  if (a.out.empty()) throw Error(ErrorCode::invalid_argument, "run: -o DIR is required");
  make_directories(a.out);  // before the scene loads: a bad folder costs nothing
  const PipelineSettings settings = a.p.settings();
  const std::unique_ptr<Pipeline> owned = a.p.pipeline(settings);
  Pipeline& pipeline = *owned;
  const std::string lighting = fmt::format(
      "{} ({}{}{})",
      pipeline.direct_lighting() == DirectLighting::nee      ? "NEE"
      : pipeline.direct_lighting() == DirectLighting::restir ? "ReSTIR, biased"
                                                             : "ReSTIR, unbiased",
      pipeline.light_sampling() == LightSampling::tree ? "light tree" : "power",
      settings.auto_lighting ? ", auto" : "", settings.radiance_cache ? ", radiance cache" : "");
  const CameraPath path =
      camera_path_for(pipeline.asset(), a.path.empty() ? "orbit:30" : a.path, a.view);
  fmt::print("scene    {} ({} triangles)\n", pipeline.source(), pipeline.triangle_count());
  fmt::print(
      "pipeline {}x{} output, internal {}x{} (x{}), denoise {}, upscale {}, {} spp, max depth {}, "
      "direct light {}\n",
      settings.width, settings.height, settings.width / settings.factor,
      settings.height / settings.factor, settings.factor,
      settings.denoise ? denoise_method_name(settings.denoiser) : "none",
      settings.factor > 1 ? upscale_method_name(settings.upscaler) : "none", settings.spp,
      settings.max_depth, lighting);
  const double t0 = path.start(), t1 = path.end();
  std::vector<PipelineTimes> times;
  std::vector<double> mrays;
  std::vector<RenderStats> stats;
  // The share of the render's thread time spent inside trace / occluded (the rest: shading).
  auto trace_share = [](const RenderStats& s) {
    return s.total_thread_ms > 0 ? s.trace_ms / s.total_thread_ms : 0.0;
  };
  std::string csv =
      "frame,factor,update_ms,render_ms,denoise_ms,upscale_ms,tonemap_ms,total_ms,mrays_per_s,"
      "camera_rays,bounce_rays,shadow_rays,trace_share\n";
  for (int i = 0; i < a.frames; ++i) {
    const double t = a.frames > 1 ? t0 + (t1 - t0) * double(i) / double(a.frames - 1) : t0;
    const PipelineFrame& f = pipeline.frame(path.at(t), t);
    const double mr = double(f.stats.rays()) / (f.times.render * 1e3);
    times.push_back(f.times), mrays.push_back(mr), stats.push_back(f.stats);
    csv += fmt::format("{},{},{:.3f},{:.3f},{:.3f},{:.3f},{:.3f},{:.3f},{:.2f},{},{},{},{:.3f}\n",
                       i, f.factor, f.times.update, f.times.render, f.times.denoise,
                       f.times.upscale, f.times.tonemap, f.times.total, mr, f.stats.camera_rays,
                       f.stats.bounce_rays, f.stats.shadow_rays, trace_share(f.stats));
    const std::string stem =
        (std::filesystem::path(a.out) / fmt::format("frame_{:04d}", i)).string();
    if (!a.no_png) write_png(stem + ".png", f.width, f.height, f.rgb8);
    if (a.exr) write_image(stem + ".exr", f.upscaled);
    if (!a.quiet)
      fmt::print(
          "frame {:4d}/{}  x{}  render {:6.1f}  denoise {:6.1f}  upscale {:5.1f}  total {:6.1f} ms "
          " ({:.1f} fps)\n",
          i + 1, a.frames, f.factor, f.times.render, f.times.denoise, f.times.upscale,
          f.times.total, 1000.0 / f.times.total);
  }
  // The table: median and p95 per stage (the first frame, warm-up, excluded when there are more).
  const size_t skip = times.size() > 1 ? 1 : 0;
  auto column = [&](double PipelineTimes::*m) {
    std::vector<double> v;
    for (size_t i = skip; i < times.size(); ++i) v.push_back(times[i].*m);
    return v;
  };
  std::string md = fmt::format(
      "# kestrel run: {}\n\n{}x{} output from {}x{} internal (x{}), denoiser {}, upsampler {}, {} "
      "spp, max depth {}, direct light {}; {} "
      "frames ({} timed, the first is warm-up).\n\n| stage | median ms | p95 ms "
      "|\n|---|---:|---:|\n",
      pipeline.source(), settings.width, settings.height, settings.width / settings.factor,
      settings.height / settings.factor, settings.factor,
      settings.denoise ? denoise_method_name(settings.denoiser) : "none",
      settings.factor > 1 ? upscale_method_name(settings.upscaler) : "none", settings.spp,
      settings.max_depth, lighting, a.frames, times.size() - skip);
  const std::pair<const char*, double PipelineTimes::*> stages[] = {
      {"scene update", &PipelineTimes::update}, {"render", &PipelineTimes::render},
      {"denoise", &PipelineTimes::denoise},     {"upscale", &PipelineTimes::upscale},
      {"tone map", &PipelineTimes::tonemap},    {"frame", &PipelineTimes::total}};
  for (const auto& [name, m] : stages) {
    const std::vector<double> v = column(m);
    md += fmt::format("| {} | {:.1f} | {:.1f} |\n", name, percentile(v, 0.5), percentile(v, 0.95));
  }
  const double med = percentile(column(&PipelineTimes::total), 0.5);
  std::vector<double> mr(mrays.begin() + std::ptrdiff_t(skip), mrays.end());
  md += fmt::format("\n{:.2f} frames per second (median frame), render {:.2f} Mrays/s (median).\n",
                    1000.0 / med, percentile(mr, 0.5));
  // Where the render's time goes: rays per frame by kind, and the share of its thread time
  // inside the traversal kernels (the rest is shading: hit data, texels, light and BSDF
  // samples, the accumulation).
  auto median_of = [&](auto&& value) {
    std::vector<double> v;
    for (size_t i = skip; i < stats.size(); ++i) v.push_back(double(value(stats[i])));
    return percentile(v, 0.5);
  };
  auto rays = [&](uint64_t RenderStats::*m) {
    return median_of([m](const RenderStats& s) { return s.*m; });
  };
  md += fmt::format(
      "Rays per frame (median): {:.0f} camera, {:.0f} bounce, {:.0f} shadow; {:.0f} % of the "
      "render's thread time inside trace / occluded (median), the rest shading.\n",
      rays(&RenderStats::camera_rays), rays(&RenderStats::bounce_rays),
      rays(&RenderStats::shadow_rays), 100.0 * median_of(trace_share));
  // The render's wall time by step (medians of each; "other": the rest of the render's median,
  // e.g. the radiance cache's merge and the frame's AOVs).
  constexpr auto fields = RenderStats::Steps::fields();
  constexpr const char* labels[] = {"camera rays",        "trace camera rays", "shade first hits",
                                    "their shadow rays",  "trace bounces",     "shade bounces",
                                    "bounce shadow rays", "add to film"};
  static_assert(std::size(labels) == fields.size());
  md += "\nRender steps (median ms):";
  double stepped = 0;
  for (size_t k = 0; k < fields.size(); ++k) {
    const auto m = fields[k].second;
    const double v = median_of([m](const RenderStats& st) { return st.steps.*m; });
    stepped += v;
    md += fmt::format(" {} {:.1f},", labels[k], v);
  }
  md += fmt::format(" other {:.1f}.\n",
                    std::max(0.0, percentile(column(&PipelineTimes::render), 0.5) - stepped));
  write_text_file((std::filesystem::path(a.out) / "timings.csv").string(), csv);
  write_text_file((std::filesystem::path(a.out) / "timings.md").string(), md);
  fmt::print("\n{}", md);
  fmt::print(
      "wrote    {} frames, timings.md and timings.csv to {}{}\n", a.frames, a.out,
      a.no_png ? ""
               : fmt::format(" (video: ffmpeg -framerate 30 -i {}/frame_%04d.png out.mp4)", a.out));
}

}  // namespace

Action add_run_command(CLI::App& cmd) {
  auto a = std::make_shared<RunArgs>();
  a->p.add_to(cmd);
  cmd.add_option(
      "--path", a->path,
      "Camera path JSON (keyframes), or orbit[:DEGREES] about --view (default orbit:30)");
  cmd.add_option("--view", a->view, "Start view of an orbit");
  cmd.add_option("--frames", a->frames, "Frames, evenly spread over the path's time span")
      ->capture_default_str();
  cmd.add_option("-o,--out", a->out, "Output directory: frame_NNNN.png, timings.md, timings.csv")
      ->required();
  cmd.add_flag("--exr", a->exr, "Also write each output frame as linear EXR");
  cmd.add_flag("--no-png", a->no_png, "No PNG frames (timings only)");
  cmd.add_flag("--quiet", a->quiet, "Only the table");
  return [a] { run(*a); };
}

}  // namespace kestrel::cli
