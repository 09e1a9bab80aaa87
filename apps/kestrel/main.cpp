// kestrel: the command-line tool. Library errors become a one-line message and exit 1.
#include <cstdio>

#include "commands.h"
#include "kestrel/error.h"

int main(int argc, char** argv) {
  CLI::App app{"kestrel: CPU ray tracing engine (BVH builders, traversal, tools)"};
  app.require_subcommand(1);
  std::vector<std::pair<CLI::App*, kestrel::cli::Action>> commands;
  auto add = [&](auto fn, const char* name, const char* help) {
    CLI::App* sub = app.add_subcommand(name, help);
    commands.push_back({sub, fn(*sub)});
  };
  add(kestrel::cli::add_bvh_command, "bvh", "Build a BVH and print build time and quality metrics");
  add(kestrel::cli::add_trace_command, "trace", "Trace a .rays file and write a .hits file");
  add(kestrel::cli::add_rays_command, "rays", "Generate a .rays file (primary, shadow or diffuse rays)");
  add(kestrel::cli::add_preview_command, "preview", "Render a shaded depth/normal PNG of a scene");
  add(kestrel::cli::add_render_command, "render", "Path-trace one frame with every AOV (EXR, PFM, PNG)");
  add(kestrel::cli::add_render_sequence_command, "render-sequence", "Path-trace a camera path, one file set per frame");
  add(kestrel::cli::add_denoise_command, "denoise", "Denoise a frame or a sequence (neural, svgf, atrous)");
  add(kestrel::cli::add_upscale_command, "upscale", "Upsample a jittered low-resolution sequence (neural, taau, bicubic, bilinear)");
  add(kestrel::cli::add_run_command, "run", "The real-time pipeline headless along a camera path: frames and stage timings");
  add(kestrel::cli::add_view_command, "view", "The real-time pipeline in a window (SDL2): WASD + mouse, stages, overlay");
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e);
  }
  try {
    for (auto& [sub, action] : commands)
      if (sub->parsed()) action();
  } catch (const kestrel::Error& e) {
    std::fprintf(stderr, "kestrel: error: %s\n", e.what());
    return 1;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "kestrel: error: %s\n", e.what());
    return 1;
  }
  return 0;
}
