// Many-light sampling: power-proportional NEE against the light tree, at equal render time,
// on the built-in lamp hall (1024 lamps, 2048 emissive triangles) and any other scene given.
// A converged reference (tree, many passes) first; then each method renders with a time
// limit (same seed, one thread by default) several times; relMSE against the reference,
// median over the runs, and the ratio tree / power. Also at equal samples per pixel.
// Then the real-time case, one frame as the loop renders it: ReSTIR DI (biased and unbiased)
// after --frames frames of a still camera (its reservoirs reused from frame to frame) against
// NEE given as many samples per pixel as fit in ReSTIR's frame time; relMSE of that one frame,
// median over the runs.
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
  int ref_spp = 2048, runs = 3, threads = 1, depth = 3, frames = 16;
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
  app.add_option("--frames", frames, "Real-time: frames of history before the measured one")
      ->capture_default_str();
  app.add_flag("--quick", quick, "Tiny run (CI)");
  CLI11_PARSE(app, argc, argv);
  try {
    if (quick) res = "64x36", seconds = 0.1, ref_spp = 64, runs = 1, frames = 3;
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

    // The real-time case: frame `frames` of a still camera, 1 spp, a fresh seed per frame.
    fmt::print(
        "\nreal time: one frame after {} frames of a still camera (a new Renderer per run)\n\n"
        "| method | spp | ms per frame | relMSE of the frame |\n|---|---:|---:|---:|\n",
        frames);
    struct Method {
      const char* name;
      LightSampling ls;
      DirectLighting d;
    };
    const Method methods[] = {
        {"ReSTIR (biased), tree", LightSampling::tree, DirectLighting::restir},
        {"ReSTIR (unbiased), tree", LightSampling::tree, DirectLighting::restir_unbiased},
        {"ReSTIR (biased), power", LightSampling::power, DirectLighting::restir}};
    auto frame_of = [&](const Method& m, int spp, uint64_t seed, double& ms) {
      Renderer rr(asset.scene());
      RenderSettings f = s;
      f.time_limit_s = 0, f.spp = spp, f.light_sampling = m.ls, f.direct = m.d;
      Frame out;
      std::vector<double> times;
      for (int k = 0; k <= frames; ++k) {
        f.frame = uint32_t(k), f.seed = seed;
        out = rr.render(*cam, f);
        if (k > 0) times.push_back(out.stats.ms);
      }
      ms = median(times);
      return relmse(out[Aov::color], ref[Aov::color]);
    };
    double restir_ms = 0, restir_rel = 0, nee_rel[2] = {0, 0};
    for (const Method& m : methods) {
      std::vector<double> errs, times;
      for (int k = 0; k < runs; ++k) {
        double ms = 0;
        errs.push_back(frame_of(m, 1, 200 + uint64_t(k), ms));
        times.push_back(ms);
      }
      if (&m == &methods[0]) restir_ms = median(times), restir_rel = median(errs);
      fmt::print("| {} | 1 | {:.1f} | {:.5f} |\n", m.name, median(times), median(errs));
    }
    // NEE: 1 spp timed, then the spp that fits in ReSTIR's frame time.
    for (LightSampling ls : {LightSampling::power, LightSampling::tree}) {
      const Method nee{"", ls, DirectLighting::nee};
      double ms1 = 0;
      frame_of(nee, 1, 300, ms1);
      const int spp = std::max(1, int(std::lround(restir_ms / std::max(ms1, 1e-3))));
      std::vector<double> errs, times;
      for (int k = 0; k < runs; ++k) {
        double ms = 0;
        errs.push_back(frame_of(nee, spp, 200 + uint64_t(k), ms));
        times.push_back(ms);
      }
      const double e = median(errs);
      fmt::print("| NEE, {} | {} | {:.1f} | {:.5f} |\n",
                 ls == LightSampling::power ? "power" : "tree", spp, median(times), e);
      nee_rel[ls == LightSampling::power ? 0 : 1] = e;
    }
    fmt::print(
        "\nReSTIR (biased, tree) / NEE at equal frame time: relMSE {:.3f} (power), {:.3f} "
        "(tree)\n",
        restir_rel / nee_rel[0], restir_rel / nee_rel[1]);
  } catch (const Error& e) {
    fmt::print(stderr, "kestrel_light_sampling_bench: {}\n", e.what());
    return 1;
  }
}
