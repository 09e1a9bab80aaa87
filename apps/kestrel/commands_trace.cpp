// `kestrel trace` (rays file in, hits file out) and `kestrel rays` (make a rays file).
#include <fmt/format.h>

#include <memory>

#include "commands.h"
#include "common/ray_gen.h"
#include "core/timer.h"
#include "kestrel/error.h"
#include "kestrel/io.h"
#include "kestrel/parallel.h"

namespace kestrel::cli {

namespace {

struct TraceArgs {
  std::string scene, rays_path, hits_path;
  BuildOptions build;
  std::string layout = "auto", isa = "auto", packets = "auto", stream = "auto";
  bool any_hit = false;
  int repeat = 3;
};

Accel load_and_build(const std::string& path, const BuildConfig& config) {
  const Scene scene = load_scene_reporting(path);
  Accel accel = build_accel(scene, config);
  if (accel.validation.report.valid_triangle_count == 0)
    throw Error(ErrorCode::invalid_geometry,
                fmt::format("{}: no valid triangle ({})", path, accel.validation.report.summary()));
  return accel;
}

// "auto" -> the library's default, "on" / "off" -> forced.
std::optional<bool> auto_on_off(const char* flag, const std::string& value) {
  if (value == "auto") return std::nullopt;
  if (value == "on" || value == "off") return value == "on";
  throw Error(ErrorCode::invalid_argument,
              fmt::format("{} '{}': expected auto, on or off", flag, value));
}

void run_trace(const TraceArgs& a) {
  BuildConfig config = a.build.config();
  auto layout = layout_from_name(a.layout);
  if (!layout)
    throw Error(ErrorCode::invalid_argument,
                fmt::format("unknown layout '{}' (auto, bvh2, bvh4, bvh8)", a.layout));
  config.layout = *layout;
  TraceOptions options;
  if (a.isa != "auto") {
    options.isa = isa_from_name(a.isa);
    if (!options.isa)
      throw Error(ErrorCode::invalid_argument,
                  fmt::format("unknown ISA '{}' (auto, sse2, avx2, avx512)", a.isa));
    if (!isa_supported(*options.isa))
      throw Error(ErrorCode::invalid_argument,
                  fmt::format("ISA '{}' is not supported by this CPU (best: {})", a.isa,
                              isa_name(host_isa())));
    set_default_isa(*options.isa);  // also picks the layout `auto` resolves to
  }
  options.packets = auto_on_off("--packets", a.packets);
  options.stream = auto_on_off("--stream", a.stream);
  std::unique_ptr<ThreadLimit> limit;
  if (a.build.threads > 0) limit = std::make_unique<ThreadLimit>(a.build.threads);
  const std::vector<Ray> rays = read_rays(a.rays_path);
  const Accel accel = load_and_build(a.scene, config);
  std::vector<Hit> hits(rays.size());
  std::vector<double> ms;
  for (int r = 0; r < std::max(1, a.repeat); ++r) {
    Timer t;
    trace(accel, rays, hits, a.any_hit, options);
    ms.push_back(t.ms());
  }
  write_hits(a.hits_path, hits);
  size_t hit_count = 0;
  for (const Hit& h : hits) hit_count += h.hit();
  const double med = median(ms);
  fmt::print("scene      {} ({})\n", a.scene, accel.validation.report.summary());
  fmt::print(
      "builder    {}{}\n", builder_name(accel.builder),
      accel.depth_fallback
          ? fmt::format(" (the {} tree was deeper than traversal allows: rebuilt by median split)",
                        builder_name(resolve_builder(config, accel.prim_count)))
          : std::string());
  fmt::print("layout     {} ({} bytes, {:.1f} bytes/prim), ISA {}, packets {}\n",
             layout_name(accel.layout), accel.memory_bytes(),
             accel.prim_count ? double(accel.memory_bytes()) / double(accel.prim_count) : 0.0,
             isa_name(options.isa.value_or(default_isa())), a.packets);
  fmt::print("build      {:.2f} ms\n", accel.build_ms);
  fmt::print("rays       {} ({}), {} hit\n", rays.size(), a.any_hit ? "any hit" : "closest hit",
             hit_count);
  fmt::print("trace      {:.2f} ms (median of {}), {:.3f} Mrays/s\n", med, ms.size(),
             med > 0 ? double(rays.size()) / (med * 1e3) : 0.0);
  fmt::print("wrote      {}\n", a.hits_path);
}

struct RaysArgs {
  std::string scene, out, kind = "primary", view = "framing", res = "640x360";
  uint64_t seed = 1;
};

void run_rays(const RaysArgs& a) {
  auto kind = tools::ray_kind_from_name(a.kind);
  if (!kind)
    throw Error(ErrorCode::invalid_argument,
                fmt::format("unknown ray kind '{}' (primary, shadow, diffuse)", a.kind));
  int w, h;
  parse_resolution(a.res, w, h);
  const Scene scene = load_scene_reporting(a.scene);
  auto cam = tools::named_view(scene, a.view);
  if (!cam)
    throw Error(ErrorCode::invalid_argument,
                fmt::format("{}: no view named '{}'", a.scene, a.view));
  const Accel accel = build_accel(scene, BuildConfig{});
  const std::vector<Ray> rays = tools::make_rays(accel, scene, *cam, w, h, *kind, a.seed);
  write_rays(a.out, rays);
  fmt::print("wrote {} {} rays to {}\n", rays.size(), a.kind, a.out);
}

}  // namespace

Action add_trace_command(CLI::App& cmd) {
  auto args = std::make_shared<TraceArgs>();
  cmd.add_option("scene", args->scene, "scene file (.obj, .gltf, .glb) or builtin:cornell_box")
      ->required();
  cmd.add_option("--rays", args->rays_path, "input .rays file")->required();
  cmd.add_option("--hits", args->hits_path, "output .hits file")->required();
  cmd.add_flag("--any-hit", args->any_hit, "occlusion query: t of any hit found, or +inf");
  cmd.add_option("--repeat", args->repeat, "timed passes (median reported)")
      ->check(CLI::Range(1, 1000));
  cmd.add_option("--layout", args->layout, "auto | bvh2 (scalar reference) | bvh4 | bvh8");
  cmd.add_option("--isa", args->isa, "auto | sse2 | avx2 | avx512 (kernel instruction set)");
  cmd.add_option("--packets", args->packets,
                 "auto | on | off: trace closest-hit rays in packets (16 rays per packet with "
                 "AVX-512, 8 otherwise)");
  cmd.add_option("--stream", args->stream,
                 "auto | on | off: trace the batch reordered by origin and direction (same hits, "
                 "in the file's order); auto: for large incoherent batches (ray streams where the "
                 "layout and ISA have them)");
  args->build.add_to(cmd);
  return [args] { run_trace(*args); };
}

Action add_rays_command(CLI::App& cmd) {
  auto args = std::make_shared<RaysArgs>();
  cmd.add_option("scene", args->scene, "scene file or builtin:NAME")->required();
  cmd.add_option("-o,--out", args->out, "output .rays file")->required();
  cmd.add_option("--kind", args->kind, "primary | shadow | diffuse");
  cmd.add_option("--view", args->view, "named view (framing; inside for Sponza)");
  cmd.add_option("--res", args->res, "WxH pixels of the primary rays");
  cmd.add_option("--seed", args->seed, "random seed for diffuse rays");
  return [args] { run_rays(*args); };
}

}  // namespace kestrel::cli
