// Many-light sampling: power-proportional NEE against the light tree, at equal render time,
// on the built-in lamp hall (1024 lamps, 2048 emissive triangles) and any other scene given.
// A converged reference (tree, many passes) first; then each method renders with a time
// limit (same seed, one thread by default) several times; relMSE against the reference,
// median over the runs, and the ratio tree / power. Also at equal samples per pixel.
#include <fmt/format.h>
#include <CLI/CLI.hpp>

#include <string>
#include <vector>

#include "image_metrics.h"
#include "kestrel/kestrel.h"

using namespace kestrel;
using bench::median;
using bench::relmse;

int main(int argc, char** argv) {
  CLI::App app{"kestrel light-sampling benchmark"};
  std::string scene = "builtin:lamp_hall", view = "inside", res = "320x180", lights;
  double seconds = 2.0;
  int ref_spp = 2048, runs = 3, threads = 1, depth = 3;
  bool quick = false;
  app.add_option("--scene", scene, "Scene")->capture_default_str();
  app.add_option("--view", view, "View")->capture_default_str();
  app.add_option("--lights", lights,
                 "A lights file added to the scene's (e.g. data/lights/sponza_100.json)");
  app.add_option("--res", res, "Resolution")->capture_default_str();
  app.add_option("--seconds", seconds, "Render time per method and run")->capture_default_str();
  app.add_option("--ref-spp", ref_spp, "Reference passes (tree)")->capture_default_str();
  app.add_option("--runs", runs, "Runs per method (median)")->capture_default_str();
  app.add_option("--threads", threads, "Threads")->capture_default_str();
  app.add_option("--max-depth", depth, "Path depth")->capture_default_str();
  app.add_flag("--quick", quick, "Tiny run (CI)");
  CLI11_PARSE(app, argc, argv);
  try {
    if (quick) res = "64x36", seconds = 0.1, ref_spp = 64, runs = 1;
    int w = 0, h = 0;
    if (std::sscanf(res.c_str(), "%dx%d", &w, &h) != 2)
      throw Error(ErrorCode::invalid_argument, "--res WxH");
    ThreadLimit limit(threads);
    Asset asset = Asset::load(scene);
    if (!lights.empty()) asset.add_lights(load_lights(lights));
    const auto cam = find_view(asset, view);
    if (!cam)
      throw Error(ErrorCode::invalid_argument, fmt::format("{}: no view '{}'", scene, view));
    Renderer r(asset.scene());
    RenderSettings s;
    s.width = w, s.height = h, s.max_depth = depth, s.seed = 7;
    s.light_sampling = LightSampling::tree;
    s.spp = ref_spp;
    const Frame ref = r.render(*cam, s);
    fmt::print(
        "scene {} ({} lights), {}x{}, depth {}, {} thread(s); reference {} spp (tree) in {:.1f} "
        "s\n\n",
        scene, r.light_count(), w, h, depth, threads, ref.stats.passes, ref.stats.ms / 1000);
    fmt::print(
        "| method | equal time: spp in {:.1f} s | relMSE | equal spp (16): relMSE "
        "|\n|---|---:|---:|---:|\n",
        seconds);
    double rel[2] = {0, 0}, rel_spp[2] = {0, 0};
    for (int m = 0; m < 2; ++m) {
      s.light_sampling = m == 0 ? LightSampling::power : LightSampling::tree;
      std::vector<double> errs, passes;
      for (int k = 0; k < runs; ++k) {
        s.seed = 100 + uint64_t(k), s.spp = 1 << 20, s.time_limit_s = seconds;
        const Frame f = r.render(*cam, s);
        errs.push_back(relmse(f[Aov::color], ref[Aov::color]));
        passes.push_back(f.stats.passes);
      }
      s.time_limit_s = 0, s.spp = 16, s.seed = 100;
      rel[m] = median(errs);
      rel_spp[m] = relmse(r.render(*cam, s)[Aov::color], ref[Aov::color]);
      fmt::print("| {} | {:.0f} | {:.5f} | {:.5f} |\n", m == 0 ? "power" : "tree", median(passes),
                 rel[m], rel_spp[m]);
    }
    fmt::print("\ntree / power relMSE: {:.3f} at equal time, {:.3f} at equal spp\n",
               rel[1] / rel[0], rel_spp[1] / rel_spp[0]);
  } catch (const Error& e) {
    fmt::print(stderr, "kestrel_light_sampling_bench: {}\n", e.what());
    return 1;
  }
}
