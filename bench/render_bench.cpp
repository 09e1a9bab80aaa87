// Renderer benchmark: inside Sponza (the named "inside" view), 1 spp, 640x360 and 1280x720.
// Per resolution: ms per frame (median over frames, each frame its own jitter and noise) on
// one thread and on every thread; in-render Mrays/s = rays traced / frame time; then the same
// frame's ray batches (captured, identical rays, same batch sizes) traced again alone by the
// same kernels: the raw Mrays/s of that mix. The ratio in-render / raw (per frame, the render
// and the retrace back to back, then the median: the machine's speed drifts) says how much of
// the render is tracing.
//
//   kestrel_render_bench [--scene F --view V] [--sun AZ,EL[,I]] [--max-depth N] [--frames 7]
//                        [--quick] [--json F]
#include <fmt/format.h>

#include <CLI/CLI.hpp>
#include <fstream>

#include "core/timer.h"
#include "kestrel/kestrel.h"
#include "kestrel/render.h"
#include "render/testing.h"

namespace {

using namespace kestrel;

struct Row {
  int width, height, threads;
  double frame_ms, trace_share, rays_per_frame, in_render_mrays, raw_mrays, ratio;
  double raw_camera, raw_bounce, raw_shadow;
};

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"kestrel_render_bench: path tracer ms/frame and in-render vs raw ray throughput"};
  std::string scene_path = std::string(KESTREL_SCENE_ROOT) + "/dabrovic_sponza/sponza.obj",
              view = "inside", json;
  std::string sun;
  int frames = 7, max_depth = 8;
  bool quick = false;
  app.add_option("--scene", scene_path, "Scene");
  app.add_option("--view", view, "Named view");
  app.add_option("--sun", sun,
                 "AZIMUTH,ELEVATION[,INTENSITY]: a sun and its physical sky (the real-time loop's "
                 "lighting inside Sponza is 30,70,12); default: the scene's (overcast sky)");
  app.add_option("--max-depth", max_depth, "Path depth (the real-time loop uses 4)")
      ->check(CLI::Range(1, 64));
  app.add_option("--frames", frames, "Frames per setting (median)");
  app.add_flag("--quick", quick, "Tiny run (CI: keeps the benchmark from rotting)");
  app.add_option("--json", json, "Write the rows as JSON");
  CLI11_PARSE(app, argc, argv);
  try {
    if (quick) scene_path = "builtin:cornell_box", view = "front", frames = 2;
    const Asset asset = Asset::load(scene_path);
    const auto camera = find_view(asset, view);
    if (!camera)
      throw Error(ErrorCode::invalid_argument, fmt::format("{}: no view '{}'", scene_path, view));
    Renderer renderer(asset.scene(), make_lighting("", sun, false));
    std::vector<std::pair<int, int>> sizes = {{640, 360}, {1280, 720}};
    if (quick) sizes = {{64, 36}};
    std::vector<int> thread_counts = {1, hardware_thread_count()};
    if (thread_counts[1] == 1) thread_counts.pop_back();
    std::vector<Row> rows;
    fmt::print("scene {} view '{}', {}, 1 spp, max depth {}, median of {} frames\n\n", scene_path,
               view, sun.empty() ? std::string("default lighting") : "sun " + sun, max_depth,
               frames);
    fmt::print(
        "| resolution | threads | ms/frame | rays/frame | in-render Mrays/s | raw Mrays/s (same "
        "rays) | in-render / raw | trace share | raw camera / bounce / shadow Mrays/s |\n");
    fmt::print("|---|---:|---:|---:|---:|---:|---:|---:|---|\n");
    for (auto [w, h] : sizes)
      for (int threads : thread_counts) {
        RenderSettings rs;
        rs.width = w, rs.height = h, rs.spp = 1, rs.threads = threads, rs.max_depth = max_depth;
        std::vector<double> ms, share, raw_ms, in_mrays, raw_mrays, rays, ratios;
        std::vector<double> kind_mrays[3];
        renderer.render(*camera, rs);  // warm-up
        for (int f = 0; f < frames; ++f) {
          rs.frame = uint32_t(f);
          const Frame fr = renderer.render(*camera, rs);
          ms.push_back(fr.stats.ms);
          share.push_back(fr.stats.trace_ms / fr.stats.total_thread_ms);
          rays.push_back(double(fr.stats.rays()));
          in_mrays.push_back(double(fr.stats.rays()) / (fr.stats.ms * 1e3));
          if (threads == 1) {
            RayCapture cap;
            RendererTesting::set_capture(renderer, &cap);
            renderer.render(*camera, rs);
            RendererTesting::set_capture(renderer, nullptr);
            std::array<double, 3> t{};
            {
              ThreadLimit one(1);
              t = RendererTesting::retrace(renderer, cap);
            }
            const double total = t[0] + t[1] + t[2];
            raw_ms.push_back(total);
            ratios.push_back(total /
                             fr.stats.ms);  // same rays: (rays / render ms) / (rays / raw ms)
            raw_mrays.push_back(double(cap.camera.size() + cap.bounce.size() + cap.shadow.size()) /
                                (total * 1e3));
            kind_mrays[0].push_back(double(cap.camera.size()) / (t[0] * 1e3));
            kind_mrays[1].push_back(double(cap.bounce.size()) / (t[1] * 1e3));
            kind_mrays[2].push_back(double(cap.shadow.size()) / (t[2] * 1e3));
          }
        }
        Row r{w, h, threads, median(ms), median(share), median(rays), median(in_mrays), 0,
              0, 0, 0,       0};
        if (threads == 1) {
          r.raw_mrays = median(raw_mrays);
          r.ratio = median(ratios);  // per frame, render and retrace back to back
          r.raw_camera = median(kind_mrays[0]), r.raw_bounce = median(kind_mrays[1]),
          r.raw_shadow = median(kind_mrays[2]);
          fmt::print(
              "| {}x{} | {} | {:.1f} | {:.0f} | {:.2f} | {:.2f} | **{:.2f}** | {:.0f}% | {:.2f} / "
              "{:.2f} / {:.2f} |\n",
              w, h, threads, r.frame_ms, r.rays_per_frame, r.in_render_mrays, r.raw_mrays, r.ratio,
              100 * r.trace_share, r.raw_camera, r.raw_bounce, r.raw_shadow);
        } else {
          fmt::print("| {}x{} | {} | {:.1f} | {:.0f} | {:.2f} | | | {:.0f}% | |\n", w, h, threads,
                     r.frame_ms, r.rays_per_frame, r.in_render_mrays, 100 * r.trace_share);
        }
        rows.push_back(r);
      }
    if (!json.empty()) {
      std::ofstream out(json);
      out << "[\n";
      for (size_t i = 0; i < rows.size(); ++i) {
        const Row& r = rows[i];
        out << fmt::format(
            "  {{\"width\": {}, \"height\": {}, \"threads\": {}, \"frame_ms\": {:.3f}, "
            "\"trace_share\": {:.4f}, "
            "\"rays_per_frame\": {:.0f}, \"in_render_mrays\": {:.4f}, \"raw_mrays\": {:.4f}, "
            "\"ratio\": {:.4f}}}{}\n",
            r.width, r.height, r.threads, r.frame_ms, r.trace_share, r.rays_per_frame,
            r.in_render_mrays, r.raw_mrays, r.ratio, i + 1 < rows.size() ? "," : "");
      }
      out << "]\n";
    }
  } catch (const std::exception& e) {
    fmt::print(stderr, "kestrel_render_bench: error: {}\n", e.what());
    return 1;
  }
  return 0;
}
