// `kestrel render` (one frame, every AOV) and `kestrel render-sequence` (a camera path,
// animated glTF scenes moving, one file set per frame).
#include <fmt/format.h>

#include <unistd.h>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <memory>

#include "commands.h"
#include "core/file_io.h"
#include "distributed/distributed.h"
#include "kestrel/denoise.h"
#include "kestrel/error.h"
#include "kestrel/io.h"
#include "kestrel/pipeline.h"
#include "kestrel/render.h"
#include "kestrel/upscale.h"

namespace kestrel::cli {

namespace {

struct RenderArgs {
  std::string scene = "builtin:cornell_box", view, camera, res = "640x360", out, pfm, png, env,
              path, denoise, upscale, sun, light_sampling = "power", lights, direct = "nee";
  bool sky = false;
  int spp = 1, max_depth = 8, threads = 0, frames = 0, frame = 0, factor = 2;
  uint64_t seed = 0;
  double time_limit = 0, time = 0;
  float exposure = 0, clamp = 0, fps = 30, indirect_rate = 1;
  bool no_jitter = false, fixed_jitter = false, quiet = false, radiance_cache = false;
};

void add_common(CLI::App& cmd, RenderArgs& a) {
  cmd.add_option("scene", a.scene, "Scene file (OBJ, glTF, GLB) or builtin:NAME")->required();
  cmd.add_option("--res", a.res, "Resolution WxH")->capture_default_str();
  cmd.add_option("--spp", a.spp, "Samples per pixel")
      ->capture_default_str()
      ->check(CLI::Range(1, 1 << 20));
  cmd.add_option("--seed", a.seed, "Random seed (same seed: same image for any thread count)")
      ->capture_default_str();
  cmd.add_option("--max-depth", a.max_depth, "Path vertices after the camera (1 = direct light)")
      ->capture_default_str()
      ->check(CLI::Range(1, 1024));
  cmd.add_option("--threads", a.threads, "Worker threads (0 = all)")
      ->capture_default_str()
      ->check(CLI::Range(0, 1024));
  cmd.add_option("--env", a.env,
                 "Environment: none | sky | constant:R,G,B | image file (.hdr .exr .pfm .png)");
  cmd.add_option("--sun", a.sun,
                 "A sun: AZIMUTH,ELEVATION[,INTENSITY] (degrees from north (-Z) towards east (+X); "
                 "irradiance, default 10); with the physical sky unless --env");
  cmd.add_flag("--sky", a.sky,
               "The physical sky (Preetham) for the sun (default sun: azimuth 135, elevation 45)");
  cmd.add_option(
      "--lights", a.lights,
      "A lights file (JSON: point / spot / directional lights, docs/renderer.md) added to "
      "the scene's");
  cmd.add_option("--light-sampling", a.light_sampling,
                 "How NEE picks a local light: power (default) | tree (a light tree: many lights)")
      ->capture_default_str();
  cmd.add_option("--direct", a.direct,
                 "Direct light at the first hit: nee (default) | restir (ReSTIR DI, biased) | "
                 "restir-unbiased")
      ->capture_default_str();
  cmd.add_flag("--radiance-cache", a.radiance_cache,
               "Paths stop at their first bounce's surface and take a world-space cache's "
               "radiance, learnt by earlier passes and frames (biased; fewer rays)");
  cmd.add_option("--pfm", a.pfm, "Also write one PFM per AOV into this directory");
  cmd.add_option("--png", a.png, "Also write the tone-mapped colour as PNG");
  cmd.add_option("--exposure", a.exposure, "Exposure of the PNG, stops")->capture_default_str();
  cmd.add_option("--clamp", a.clamp, "Clamp sample radiance to this (biased; 0 = off)")
      ->capture_default_str();
  cmd.add_option("--indirect-rate", a.indirect_rate,
                 "Share of pixels that trace a first bounce per pass: 1 | 0.5 (a checkerboard) | "
                 "0.25; the others keep their direct light (unbiased, noisier)")
      ->capture_default_str();
  cmd.add_flag("--no-jitter", a.no_jitter, "Sample pixel centres (no Halton jitter)");
  cmd.add_flag("--fixed-jitter", a.fixed_jitter,
               "Every sample at the frame's jitter (point-sampled, as an upsampler's input)");
  cmd.add_flag("--quiet", a.quiet, "No progress bar");
  cmd.add_option(
      "--denoise", a.denoise,
      "Denoise the colour AOV: neural | svgf | atrous | rae (the noisy one is kept as layer "
      "'noisy' / noisy.pfm)");
}

RenderSettings settings_of(const RenderArgs& a) {
  RenderSettings s;
  parse_resolution(a.res, s.width, s.height);
  s.spp = a.spp;
  s.seed = a.seed;
  s.max_depth = a.max_depth;
  s.threads = a.threads;
  s.time_limit_s = a.time_limit;
  s.jitter = !a.no_jitter;
  s.fixed_jitter = a.fixed_jitter;
  s.clamp = a.clamp;
  s.indirect_rate = a.indirect_rate;
  s.radiance_cache = a.radiance_cache;
  s.progress = !a.quiet && isatty(2);
  if (a.light_sampling == "tree")
    s.light_sampling = LightSampling::tree;
  else if (a.light_sampling != "power")
    throw Error(ErrorCode::invalid_argument,
                fmt::format("--light-sampling '{}': expected power or tree", a.light_sampling));
  const auto direct = direct_lighting_from_name(a.direct);
  if (!direct)
    throw Error(ErrorCode::invalid_argument,
                fmt::format("--direct '{}': expected nee, restir or restir-unbiased", a.direct));
  s.direct = *direct;
  return s;
}

std::optional<Environment> environment_of(const RenderArgs& a) {
  return make_lighting(a.env, a.sun, a.sky);
}

Camera parse_camera(const std::string& text) {
  std::vector<float> v;
  size_t at = 0;
  while (at <= text.size()) {
    const size_t comma = text.find(',', at);
    const std::string part =
        text.substr(at, comma == std::string::npos ? std::string::npos : comma - at);
    char* end = nullptr;
    const float x = std::strtof(part.c_str(), &end);
    if (part.empty() || end != part.c_str() + part.size())
      throw Error(ErrorCode::invalid_argument,
                  fmt::format("--camera '{}': '{}' is not a number", text, part));
    v.push_back(x);
    if (comma == std::string::npos) break;
    at = comma + 1;
  }
  if (v.size() != 6 && v.size() != 7 && v.size() != 9)
    throw Error(
        ErrorCode::invalid_argument,
        fmt::format("--camera '{}': expected ex,ey,ez,tx,ty,tz[,vfov[,aperture,focus]]", text));
  Camera c;
  c.eye = {v[0], v[1], v[2]};
  c.target = {v[3], v[4], v[5]};
  if (v.size() >= 7) c.vfov_degrees = v[6];
  if (v.size() == 9) c.aperture_radius = v[7], c.focus_distance = v[8];
  check_camera(c);
  return c;
}

std::unique_ptr<Denoiser> denoiser_of(const RenderArgs& a) {
  if (a.denoise.empty()) return nullptr;
  const auto m = denoise_method_from_name(a.denoise);
  if (!m)
    throw Error(ErrorCode::invalid_argument,
                fmt::format("--denoise '{}': expected neural, svgf or atrous", a.denoise));
  DenoiserOptions o;
  o.method = *m;
  return std::make_unique<Denoiser>(o);
}

// Files of one command written as a set: each to a temporary name beside its destination,
// then all renamed at the end, so a failed or killed run never leaves a half-written file in
// place of an existing one. Temporaries not committed are removed.
class FileSet {
 public:
  ~FileSet() {
    for (const auto& [tmp, final_path] : files_) std::remove(tmp.c_str());
  }
  /// A temporary path for `final_path` (same folder, same extension).
  std::string add(const std::string& final_path) {
    const std::filesystem::path p(final_path);
    const std::string tmp =
        (p.parent_path() /
         fmt::format(".{}.partial-{}{}", p.filename().string(), getpid(), p.extension().string()))
            .string();
    files_.emplace_back(tmp, final_path);
    return tmp;
  }
  void commit() {
    for (const auto& [tmp, final_path] : files_) {
      std::error_code ec;
      std::filesystem::rename(tmp, final_path, ec);
      if (ec)
        throw Error(ErrorCode::io_error,
                    fmt::format("{}: cannot replace the file: {}", final_path, ec.message()));
    }
    files_.clear();
  }

 private:
  std::vector<std::pair<std::string, std::string>> files_;
};

// With a denoised colour, the colour AOV becomes it and the noisy one is written beside it
// (EXR layer "noisy", noisy.pfm).
void write_outputs(const Frame& frame, const std::string& exr, const std::string& pfm,
                   const std::string& png, float exposure, const FloatImage* denoised = nullptr) {
  Frame copy;
  if (denoised) {
    copy = frame;
    copy.aov[int(Aov::color)] = *denoised;
  }
  const Frame& f = denoised ? copy : frame;
  const FloatImage& noisy = frame[Aov::color];
  FileSet files;
  if (!exr.empty()) {
    make_parent_directories(exr);
    if (denoised) {
      std::vector<ImageLayer> layers = f.layers();
      layers.push_back({"noisy", {"R", "G", "B"}, noisy});
      write_exr(files.add(exr), layers);
    } else {
      write_frame_exr(files.add(exr), f);
    }
  }
  if (!pfm.empty()) {
    make_directories(pfm);
    for (int a = 0; a < aov_count; ++a)
      write_pfm(
          files.add(
              (std::filesystem::path(pfm) / (std::string(aov_name(Aov(a))) + ".pfm")).string()),
          f.aov[a]);
    if (denoised) write_pfm(files.add((std::filesystem::path(pfm) / "noisy.pfm").string()), noisy);
  }
  if (!png.empty())
    write_png(files.add(png), f.width, f.height, tonemap_srgb8(f[Aov::color], exposure));
  files.commit();
}

FloatImage denoise_frame(Denoiser& d, const Frame& f) {
  return d.denoise({&f[Aov::color], &f[Aov::albedo], &f[Aov::normal], &f[Aov::depth],
                    &f[Aov::roughness], &f[Aov::motion]});
}

void print_stats(const RenderStats& st) {
  const double mrays = double(st.rays()) / (st.ms * 1e3);
  fmt::print(
      "render   {} spp in {:.1f} ms: {} camera + {} bounce + {} shadow rays, {:.2f} Mrays/s; "
      "{:.0f}% of thread time in trace/occluded\n",
      st.passes, st.ms, st.camera_rays, st.bounce_rays, st.shadow_rays, mrays,
      st.total_thread_ms > 0 ? 100.0 * st.trace_ms / st.total_thread_ms : 0.0);
}

// Per-rank busy time under mpirun: how evenly the dynamic tiles spread.
void print_ranks(const std::vector<distributed::RankStats>& ranks, double frame_ms) {
  if (ranks.size() < 2) return;
  double busy = 0;
  for (const auto& r : ranks) busy += r.busy_ms;
  for (size_t r = 0; r < ranks.size(); ++r)
    fmt::print("rank {:<3} {:5} tiles, busy {:.1f} ms ({:.0f}% of the frame)\n", r, ranks[r].tiles,
               ranks[r].busy_ms, frame_ms > 0 ? 100.0 * ranks[r].busy_ms / frame_ms : 0.0);
  fmt::print("ranks    {}: parallel efficiency {:.3f} (busy time / (ranks x frame time))\n",
             ranks.size(), frame_ms > 0 ? busy / (double(ranks.size()) * frame_ms) : 0.0);
}

// Every destination checked before the work starts: a bad --png must not cost a render, nor
// leave -o replaced and --png missing.
void check_destinations(const std::string& exr, const std::string& pfm, const std::string& png) {
  if (!exr.empty() && lower_extension(exr) != ".exr")
    throw Error(ErrorCode::invalid_argument,
                fmt::format("{}: -o writes a multi-layer EXR, so its name must end in .exr (for a "
                            "PNG give --png)",
                            exr));
  if (!png.empty() && lower_extension(png) != ".png")
    throw Error(ErrorCode::invalid_argument,
                fmt::format("{}: --png writes a PNG, so its name must end in .png", png));
  if (!exr.empty()) {
    make_parent_directories(exr);
    check_writable_destination(exr);
  }
  if (!pfm.empty()) {
    make_directories(pfm);
    check_writable_destination((std::filesystem::path(pfm) / "color.pfm").string());
  }
  if (!png.empty()) check_writable_destination(png);
}

void run_render(const RenderArgs& a) {
  if (a.out.empty() && a.pfm.empty() && a.png.empty())
    throw Error(ErrorCode::invalid_argument,
                "render: nothing to write (give -o out.exr, --pfm DIR or --png out.png)");
  if (!std::isfinite(a.exposure))
    throw Error(ErrorCode::invalid_argument,
                fmt::format("render: --exposure {} is not a finite number of stops", a.exposure));
  if (distributed::rank() == 0) check_destinations(a.out, a.pfm, a.png);
  if (!a.view.empty() && !a.camera.empty())
    throw Error(ErrorCode::invalid_argument, "render: give --view or --camera, not both");
  const RenderSettings s = settings_of(a);
  Asset asset = load_asset_reporting(a.scene);
  if (!a.lights.empty()) asset.add_lights(load_lights(a.lights));
  Camera camera;
  if (!a.camera.empty()) {
    camera = parse_camera(a.camera);
  } else {
    std::string view = a.view;
    if (view.empty()) view = find_view(asset, "front") ? "front" : "framing";
    auto c = find_view(asset, view);
    if (!c)
      throw Error(ErrorCode::invalid_argument,
                  fmt::format("{}: no view named '{}' (looked in {})", a.scene, view,
                              fmt::join(view_files_for(asset.source()), ", ")));
    camera = *c;
  }
  const std::string source = asset.source();
  const size_t triangles = asset.triangle_count();
  Renderer renderer(asset.scene(), environment_of(a));
  RenderSettings rs = s;
  rs.frame = uint32_t(a.frame);
  const std::unique_ptr<Denoiser> denoiser = denoiser_of(a);
  std::vector<distributed::RankStats> ranks;
  const Frame f = distributed::render(renderer, camera, rs, std::nullopt, &ranks);
  if (distributed::rank() != 0) return;  // rank 0 holds the frame and writes the files
  fmt::print("scene    {} ({} triangles, {} lights)\n", source, triangles, renderer.light_count());
  print_stats(f.stats);
  print_ranks(ranks, f.stats.ms);
  const FloatImage denoised = denoiser ? denoise_frame(*denoiser, f) : FloatImage{};
  write_outputs(f, a.out, a.pfm, a.png, a.exposure, denoiser ? &denoised : nullptr);
  for (const std::string& o : {a.out, a.pfm, a.png})
    if (!o.empty()) fmt::print("wrote    {}\n", o);
}

// The frames go through the Pipeline (the one frame loop): the scene posed at each frame's
// time, rendered (distributed under mpirun), denoised and upsampled as asked.
void run_sequence(const RenderArgs& a) {
  if (a.frames <= 0)
    throw Error(ErrorCode::invalid_argument,
                fmt::format("render-sequence: --frames must be positive, got {}", a.frames));
  if (a.out.empty())
    throw Error(ErrorCode::invalid_argument, "render-sequence: -o DIR is required");
  const RenderSettings s = settings_of(a);
  PipelineSettings ps;
  ps.width = s.width, ps.height = s.height, ps.spp = s.spp, ps.max_depth = s.max_depth,
  ps.clamp = s.clamp, ps.radiance_cache = s.radiance_cache, ps.indirect_rate = s.indirect_rate;
  ps.seed = s.seed, ps.threads = s.threads, ps.jitter = s.jitter, ps.fixed_jitter = s.fixed_jitter;
  ps.exposure = a.exposure;
  ps.factor = 1;
  ps.denoise = !a.denoise.empty();
  if (ps.denoise) {
    const auto m = denoise_method_from_name(a.denoise);
    if (!m)
      throw Error(ErrorCode::invalid_argument,
                  fmt::format("--denoise '{}': expected neural, svgf or atrous", a.denoise));
    ps.denoiser = *m;
  }
  if (!a.upscale.empty()) {  // --res is the output; render at 1/factor, every sample at the frame's
                             // jitter
    const auto m = upscale_method_from_name(a.upscale);
    if (!m)
      throw Error(ErrorCode::invalid_argument, fmt::format("--upscale '{}': expected one of {}",
                                                           a.upscale, upscale_method_list()));
    if (a.factor != 2 && a.factor != 4)
      throw Error(ErrorCode::invalid_argument,
                  fmt::format("render-sequence: --factor must be 2 or 4, got {}", a.factor));
    if (s.width % a.factor || s.height % a.factor)
      throw Error(ErrorCode::invalid_argument,
                  fmt::format("render-sequence: --res {} is not divisible by --factor {}", a.res,
                              a.factor));
    ps.upscaler = *m, ps.factor = a.factor, ps.fixed_jitter = true;
  }
  make_directories(a.out);
  ps.sun = a.sun, ps.sky = a.sky;
  Asset asset = load_asset_reporting(a.scene);
  if (!a.lights.empty()) asset.add_lights(load_lights(a.lights));
  Pipeline pipeline(std::move(asset), ps, a.env);
  pipeline.set_render_function(
      [](Renderer& r, const Camera& cam, const RenderSettings& rs,
         const std::optional<Camera>& prev) { return distributed::render(r, cam, rs, prev); });
  const CameraPath path = camera_path_for(pipeline.asset(), a.path, a.view);
  const double t0 = path.start(), t1 = path.end();
  for (int i = 0; i < a.frames; ++i) {
    const double t = a.frames > 1 ? t0 + (t1 - t0) * double(i) / double(a.frames - 1) : t0;
    const PipelineFrame& o = pipeline.frame(path.at(t), t);
    if (distributed::rank() != 0) continue;  // rank 0 holds the frames and writes the files
    Frame f = o.render;
    f.aov[int(Aov::color)] = o.noisy;
    const std::string name = fmt::format("frame_{:04d}", i);
    const std::string stem = (std::filesystem::path(a.out) / name).string();
    const std::string pfm_dir = a.pfm.empty() ? "" : (std::filesystem::path(a.pfm) / name).string();
    const FloatImage* denoised = ps.denoise ? &o.denoised : nullptr;
    if (ps.factor > 1) {  // the low-resolution frame under low/, the upsampled colour as the frame
      write_outputs(f, (std::filesystem::path(a.out) / "low" / (name + ".exr")).string(), pfm_dir,
                    "", a.exposure, denoised);
      write_image(stem + ".exr", o.upscaled);
      if (!a.png.empty()) write_png(stem + ".png", o.width, o.height, o.rgb8);
    } else {
      write_outputs(f, stem + ".exr", pfm_dir, a.png.empty() ? "" : stem + ".png", a.exposure,
                    denoised);
    }
    if (!a.quiet)
      fmt::print("frame {:4d}/{}  t = {:.3f} s  {:.1f} ms  {:.2f} Mrays/s\n", i + 1, a.frames, t,
                 o.stats.ms, double(o.stats.rays()) / (o.stats.ms * 1e3));
  }
  if (distributed::rank() == 0) fmt::print("wrote    {} frames to {}\n", a.frames, a.out);
}

}  // namespace

Action add_render_command(CLI::App& cmd) {
  auto a = std::make_shared<RenderArgs>();
  add_common(cmd, *a);
  cmd.add_option("--view", a->view,
                 "Named view (scene's .views.json or data/views; 'framing' always exists)");
  cmd.add_option("--camera", a->camera, "Camera ex,ey,ez,tx,ty,tz[,vfov[,aperture,focus]]");
  cmd.add_option("-o,--out", a->out, "Multi-layer EXR with every AOV");
  cmd.add_option("--time-limit", a->time_limit,
                 "Stop accumulating after this many seconds (progressive)");
  cmd.add_option("--frame", a->frame, "Frame index (Halton jitter, noise decorrelation)")
      ->capture_default_str();
  return [a] { run_render(*a); };
}

Action add_render_sequence_command(CLI::App& cmd) {
  auto a = std::make_shared<RenderArgs>();
  add_common(cmd, *a);
  cmd.add_option("--path", a->path, "Camera path JSON (keyframes), or orbit[:DEGREES] about --view")
      ->required();
  cmd.add_option("--view", a->view, "Start view of --path orbit (default: front, else framing)");
  cmd.add_option("--frames", a->frames, "Frames, evenly spread over the path's time span")
      ->required()
      ->check(CLI::Range(1, 1000000));
  cmd.add_option(
      "--upscale", a->upscale,
      "Render at --res / --factor (fixed jitter), then upsample: " + upscale_method_list(" | ") +
          " (frame_NNNN.exr: the upsampled colour; low/: the low-resolution frames)");
  cmd.add_option("--factor", a->factor, "Upsampling factor, 2 or 4")->capture_default_str();
  cmd.add_option("-o,--out", a->out,
                 "Output directory: frame_NNNN.exr (+ .png with --png x, PFMs under --pfm DIR)")
      ->required();
  return [a] { run_sequence(*a); };
}

}  // namespace kestrel::cli
