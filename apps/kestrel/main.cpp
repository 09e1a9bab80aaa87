// kestrel: the command-line tool. Library errors become a one-line message and exit 1.
#include <cstdio>
#include <new>
#include <stdexcept>
#include <string>

#include "commands.h"
#include "common/openmp_env.h"
#include "distributed/distributed.h"
#include "kestrel/error.h"
#include "kestrel/upscale.h"

int main(int argc, char** argv) {
  kestrel::cli::passive_openmp_for_onednn(argc, argv);  // first: it may execute kestrel again
  kestrel::distributed::init(&argc, &argv);  // under mpirun: one rank of many (docs/distributed.md)
  CLI::App app{"kestrel: CPU ray tracing engine (BVH builders, traversal, tools)"};
  app.require_subcommand(1);
  std::vector<std::pair<CLI::App*, kestrel::cli::Action>> commands;
  auto add = [&](auto fn, const char* name, const std::string& help) {
    CLI::App* sub = app.add_subcommand(name, help);
    commands.push_back({sub, fn(*sub)});
  };
  add(kestrel::cli::add_bvh_command, "bvh", "Build a BVH and print build time and quality metrics");
  add(kestrel::cli::add_trace_command, "trace", "Trace a .rays file and write a .hits file");
  add(kestrel::cli::add_rays_command, "rays",
      "Generate a .rays file (primary, shadow or diffuse rays)");
  add(kestrel::cli::add_preview_command, "preview", "Render a shaded depth/normal PNG of a scene");
  add(kestrel::cli::add_render_command, "render",
      "Path-trace one frame with every AOV (EXR, PFM, PNG)");
  add(kestrel::cli::add_render_sequence_command, "render-sequence",
      "Path-trace a camera path, one file set per frame");
  add(kestrel::cli::add_denoise_command, "denoise",
      "Denoise a frame or a sequence (neural, svgf, atrous, rae)");
  add(kestrel::cli::add_upscale_command, "upscale",
      "Upsample a jittered low-resolution sequence (" + kestrel::upscale_method_list() + ")");
  add(kestrel::cli::add_run_command, "run",
      "The real-time pipeline headless along a camera path: frames and stage timings");
  add(kestrel::cli::add_view_command, "view",
      "The real-time pipeline in a window (SDL2): WASD + mouse, stages, overlay");
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    const int code = app.exit(e);
    kestrel::distributed::finalize();
    return code;
  }
  try {
    for (auto& [sub, action] : commands) {
      if (!sub->parsed()) continue;
      const std::string name = sub->get_name();
      if (kestrel::distributed::size() > 1 && name != "render" && name != "render-sequence")
        throw kestrel::Error(kestrel::ErrorCode::unsupported,
                             "only render and render-sequence run distributed; run `kestrel " +
                                 name + "` without mpirun");
      action();
    }
  } catch (const std::exception& e) {
    // kestrel::Error says what went wrong with which file; anything else is named plainly
    // (no std:: text: "std::bad_alloc" tells a user nothing).
    std::string message = e.what();
    if (dynamic_cast<const std::bad_alloc*>(&e) || dynamic_cast<const std::length_error*>(&e))
      message = "out of memory: the input asks for more memory than this machine has";
    else if (!dynamic_cast<const kestrel::Error*>(&e))
      message = "internal error (" + message + "); please report it with the command line";
    // Under mpirun one rank's error ends every rank (mpirun then exits non-zero).
    if (kestrel::distributed::size() > 1) kestrel::distributed::abort_all("error: " + message);
    std::fprintf(stderr, "kestrel: error: %s\n", message.c_str());
    return 1;
  }
  kestrel::distributed::finalize();
  return 0;
}
