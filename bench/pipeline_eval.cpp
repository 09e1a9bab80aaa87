// kestrel_pipeline_eval: the whole real-time loop (1-spp render -> denoiser -> upsampler ->
// tone map, kestrel::Pipeline) against references, and its speed.
//  - Quality: on the held-out test clips of scripts/upscale/make_dataset.py (same scenes,
//    camera paths, frame times, path depth and clamp as the references), the output of
//    neural denoiser + neural upsampler vs SVGF-like + TAAU-like, at factors 2 and 4: PSNR and
//    SSIM on tone-mapped sRGB, tErr.
//  - Speed: inside Sponza (data/paths/sponza_walk.json), 1280x720 output from 640x360 and
//    320x180, the machine's threads: per-stage median and p95, frames per second.
// Writes docs/pipeline/eval.md and eval.json.
#include <fmt/format.h>
#include <tbb/global_control.h>
#include <CLI/CLI.hpp>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "common/openmp_env.h"
#include "common/views.h"
#include "image_metrics.h"
#include "kestrel/error.h"
#include "kestrel/io.h"
#include "kestrel/pipeline.h"

using namespace kestrel;
using namespace kestrel::bench;
namespace fs = std::filesystem;

namespace {

struct Config {
  const char* name;
  DenoiseMethod denoiser;
  UpscaleMethod upscaler;
};

const Config kConfigs[] = {{"SVGF-like + TAAU-like", DenoiseMethod::svgf, UpscaleMethod::taau},
                           {"neural + neural", DenoiseMethod::neural, UpscaleMethod::neural}};

double percentile(std::vector<double> v, double q) {
  std::sort(v.begin(), v.end());
  return v[std::min(v.size() - 1, size_t(q * double(v.size() - 1) + 0.5))];
}

}  // namespace

int main(int argc, char** argv) {
  kestrel::cli::passive_openmp_for_onednn(argc, argv);  // common/openmp_env.h
  std::string dataset = std::string(KESTREL_SOURCE_DIR) + "/out/upscale_dataset";
  std::string out_dir = std::string(KESTREL_SOURCE_DIR) + "/docs/pipeline";
  std::string timing_scene =
      std::string(KESTREL_SOURCE_DIR) + "/../shared/scenes/dabrovic_sponza/sponza.obj";
  std::string timing_path = std::string(KESTREL_SOURCE_DIR) + "/data/paths/sponza_walk.json";
  int threads = int(std::thread::hardware_concurrency()), timing_frames = 12;
  std::vector<int> depths;
  std::string depth_list = "4,2";
  bool quick = false;
  float indirect_rate = 1.0f;
  bool radiance_cache = false;
  CLI::App app{"kestrel_pipeline_eval: the real-time loop, speed and quality"};
  app.add_option("--dataset", dataset, "The dataset of scripts/upscale/make_dataset.py")
      ->capture_default_str();
  app.add_option("--out", out_dir, "Where eval.md and eval.json go")->capture_default_str();
  app.add_option("--threads", threads, "Worker threads")->capture_default_str();
  app.add_option("--timing-scene", timing_scene, "Scene of the speed measurement")
      ->capture_default_str();
  app.add_option("--timing-path", timing_path, "Its camera path")->capture_default_str();
  app.add_option("--timing-frames", timing_frames, "Timed frames")->capture_default_str();
  app.add_option("--indirect-rate", indirect_rate,
                 "PipelineSettings::indirect_rate of every run: 1, 0.5 or 0.25")
      ->capture_default_str();
  app.add_flag("--radiance-cache", radiance_cache,
               "Every run with the radiance cache (kestrel run's default; the references are "
               "full paths either way)");
  app.add_option("--max-depths", depth_list, "Path depths of the speed measurement")
      ->capture_default_str();
  app.add_flag("--quick", quick, "Three frames per clip and per speed setting (smoke test)");
  CLI11_PARSE(app, argc, argv);
  depths.clear();
  std::stringstream list(depth_list);
  for (std::string d; std::getline(list, d, ',');) depths.push_back(std::atoi(d.c_str()));
  if (depths.empty() || *std::min_element(depths.begin(), depths.end()) <= 0) {
    fmt::print(stderr,
               "kestrel_pipeline_eval: --max-depths '{}': expected positive numbers, e.g. 4,2\n",
               depth_list);
    return 2;
  }
  tbb::global_control threads_limit(tbb::global_control::max_allowed_parallelism,
                                    size_t(std::max(threads, 1)));
  try {
    fs::create_directories(out_dir);
    std::string md = fmt::format(
        "# Real-time pipeline evaluation\n\nWritten by `kestrel_pipeline_eval` "
        "(bench/pipeline_eval.cpp). Every run: radiance cache {}, indirect rate {}.\n\n",
        radiance_cache ? "on" : "off", indirect_rate);
    nlohmann::json js;
    // Speed.
    md += fmt::format(
        "## Speed: {} along {}, 1280x720 output, {} threads, 1 spp, neural denoiser and "
        "upsampler\n\n",
        fs::path(timing_scene).filename().string(), fs::path(timing_path).filename().string(),
        threads);
    md +=
        "| path depth | internal | factor | update | render | denoise | upscale | tone map | frame "
        "(median) | frame (p95) | fps | Mrays/s |\n"
        "|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n";
    if (!quick || fs::exists(timing_scene) || timing_scene.rfind("builtin:", 0) == 0) {
      const CameraPath path = tools::camera_path_for(Asset::load(timing_scene), timing_path, "");
      for (int max_depth : depths)
        for (int factor : {2, 4}) {
          PipelineSettings s;
          s.width = 1280, s.height = 720, s.factor = factor, s.max_depth = max_depth;
          s.indirect_rate = indirect_rate, s.radiance_cache = radiance_cache;
          Pipeline p(timing_scene, s);
          const int n = quick ? 3 : timing_frames;
          std::vector<double> st[6], mr;
          for (int i = 0; i < n + 1; ++i) {
            const double t = path.start() + (path.end() - path.start()) * double(i) / double(n);
            const PipelineFrame& f = p.frame(path.at(t), t);
            if (i == 0) continue;  // warm-up
            const double v[6] = {f.times.update,  f.times.render,  f.times.denoise,
                                 f.times.upscale, f.times.tonemap, f.times.total};
            for (int k = 0; k < 6; ++k) st[k].push_back(v[k]);
            mr.push_back(double(f.stats.rays()) / (f.times.render * 1e3));
          }
          const double med = percentile(st[5], 0.5);
          md += fmt::format(
              "| {} | {}x{} | {} | {:.1f} | {:.1f} | {:.1f} | {:.1f} | {:.1f} | {:.1f} | {:.1f} | "
              "{:.2f} | {:.2f} |\n",
              max_depth, 1280 / factor, 720 / factor, factor, percentile(st[0], 0.5),
              percentile(st[1], 0.5), percentile(st[2], 0.5), percentile(st[3], 0.5),
              percentile(st[4], 0.5), med, percentile(st[5], 0.95), 1000 / med,
              percentile(mr, 0.5));
          js["speed"].push_back({{"max_depth", max_depth},
                                 {"factor", factor},
                                 {"render_ms", percentile(st[1], 0.5)},
                                 {"denoise_ms", percentile(st[2], 0.5)},
                                 {"upscale_ms", percentile(st[3], 0.5)},
                                 {"frame_ms", med},
                                 {"frame_p95_ms", percentile(st[5], 0.95)},
                                 {"fps", 1000 / med},
                                 {"mrays", percentile(mr, 0.5)}});
          fmt::print("speed depth {} x{}: {:.1f} ms per frame ({:.2f} fps), render {:.1f} ms\n",
                     max_depth, factor, med, 1000 / med, percentile(st[1], 0.5));
        }
      md += "\nStages in ms (median over the frames after a warm-up frame).\n\n";
    }
    // Quality.
    std::ifstream mf(fs::path(dataset) / "manifest.json");
    if (!mf)
      throw Error(ErrorCode::io_error,
                  fmt::format("{}/manifest.json: not found (run scripts/upscale/make_dataset.py)",
                              dataset));
    const nlohmann::json manifest = nlohmann::json::parse(mf);
    std::map<int, std::map<std::string, std::array<double, 4>>> total;
    std::string per_clip;
    for (const auto& [clip, c] : manifest.at("clips").items()) {
      if (c.at("split") != "test") continue;
      const std::string scene = c.at("scene"), path_spec = c.at("path");
      std::string env = c.value("env", std::string("default"));
      // The render flags the clip's references were made with (make_dataset.py's "flags"):
      // the environment, a lights file, the light sampling, a sun and the sky.
      std::string lights, sun;
      bool sky = false, tree = false;
      const std::vector<std::string> flags = c.value("flags", std::vector<std::string>{});
      for (size_t i = 0; i < flags.size(); ++i) {
        const bool has_value = i + 1 < flags.size();
        if (flags[i] == "--env" && has_value)
          env = flags[++i];
        else if (flags[i] == "--lights" && has_value)
          lights = flags[++i];
        else if (flags[i] == "--light-sampling" && has_value)
          tree = flags[++i] == "tree";
        else if (flags[i] == "--sun" && has_value)
          sun = flags[++i];
        else if (flags[i] == "--sky")
          sky = true;
        else
          throw Error(ErrorCode::parse_error,
                      fmt::format("{}: render flag '{}' is not supported here", clip, flags[i]));
      }
      int w = 0, h = 0;
      if (std::sscanf(std::string(c.at("res")).c_str(), "%dx%d", &w, &h) != 2)
        throw Error(ErrorCode::parse_error, clip + ": bad res");
      int frames = c.at("frames");
      if (quick) frames = std::min(frames, 3);
      const CameraPath path = tools::camera_path_for(Asset::load(scene), path_spec, "");
      std::vector<FloatImage> refs;
      std::vector<std::vector<float>> refs_tm;
      for (int t = 0; t < frames; ++t) {
        refs.push_back(read_pfm((fs::path(dataset) / clip / "full" / "pfm" /
                                 fmt::format("frame_{:04d}", t) / "color.pfm")
                                    .string()));
        refs_tm.push_back(tonemapped(refs.back()));
      }
      for (int factor : {2, 4}) {
        for (const Config& cfg : kConfigs) {
          PipelineSettings s;
          s.width = w, s.height = h, s.factor = factor, s.denoiser = cfg.denoiser,
          s.upscaler = cfg.upscaler;
          s.max_depth = c.value("max_depth", 3), s.clamp = c.value("clamp", 8.0f);
          s.indirect_rate = indirect_rate, s.radiance_cache = radiance_cache;
          s.sun = sun, s.sky = sky;
          if (tree) s.light_sampling = LightSampling::tree;
          Asset asset = Asset::load(scene);
          if (!lights.empty()) asset.add_lights(load_lights(lights));
          Pipeline p(std::move(asset), s, env == "default" ? "" : env);
          double ps = 0, ss = 0, te = 0;
          std::vector<float> prev;
          for (int t = 0; t < frames; ++t) {
            const int all = c.at("frames");
            const double time =
                all > 1 ? path.start() + (path.end() - path.start()) * double(t) / double(all - 1)
                        : path.start();
            const PipelineFrame& f = p.frame(path.at(time), time);
            const std::vector<float> to = tonemapped(f.upscaled);
            ps += psnr(to, refs_tm[size_t(t)]);
            ss += ssim(to, refs_tm[size_t(t)], w, h);
            if (t > 0) {
              double e = 0;
              for (size_t i = 0; i < to.size(); ++i)
                e += std::abs((to[i] - prev[i]) -
                              (refs_tm[size_t(t)][i] - refs_tm[size_t(t - 1)][i]));
              te += e / double(to.size());
            }
            prev = to;
          }
          ps /= frames, ss /= frames, te /= std::max(frames - 1, 1);
          per_clip += fmt::format("| {} | x{} | {} | {:.2f} | {:.4f} | {:.5f} |\n", clip, factor,
                                  cfg.name, ps, ss, te);
          fmt::print("{:18s} x{} {:24s} PSNR {:6.2f} SSIM {:.4f} tErr {:.5f}\n", clip, factor,
                     cfg.name, ps, ss, te);
          auto& tt = total[factor][cfg.name];
          tt[0] += ps, tt[1] += ss, tt[2] += te, tt[3] += 1;
          js["clips"].push_back({{"clip", clip},
                                 {"factor", factor},
                                 {"config", cfg.name},
                                 {"psnr", ps},
                                 {"ssim", ss},
                                 {"terr", te}});
        }
      }
    }
    md +=
        "## Quality: held-out clips (1 spp per frame, references of many samples at the output "
        "resolution)\n\n"
        "The test clips of `" +
        fs::relative(dataset, KESTREL_SOURCE_DIR).string() +
        "` (scripts/upscale/make_dataset.py): each clip's scene, camera path, frame times, path "
        "depth, clamp and render flags (environment, lights, light sampling, sun, sky), rendered "
        "by the pipeline at 1 spp and compared with the clip's full-resolution reference. Means "
        "over clips.\n\n"
        "| factor | pipeline | PSNR dB | SSIM | tErr |\n|---|---|---:|---:|---:|\n";
    for (auto& [factor, m] : total)
      for (const Config& cfg : kConfigs) {
        const auto& t = m[cfg.name];
        md += fmt::format("| x{} | {} | {:.2f} | {:.4f} | {:.5f} |\n", factor, cfg.name,
                          t[0] / t[3], t[1] / t[3], t[2] / t[3]);
      }
    md +=
        "\n### Per clip\n\n| clip | factor | pipeline | PSNR dB | SSIM | tErr "
        "|\n|---|---|---|---:|---:|---:|\n" +
        per_clip;
    std::ofstream((fs::path(out_dir) / "eval.md").string()) << md;
    std::ofstream((fs::path(out_dir) / "eval.json").string()) << js.dump(1);
    fmt::print("wrote {}/eval.md and eval.json\n", out_dir);
  } catch (const Error& e) {
    fmt::print(stderr, "kestrel_pipeline_eval: {}\n", e.what());
    return 1;
  }
  return 0;
}
