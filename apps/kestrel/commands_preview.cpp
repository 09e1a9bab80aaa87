// `kestrel preview`: builds the BVH and writes a shaded depth/normal PNG (the README's main
// job on the built-in Cornell box until the path tracer lands).
#include <fmt/format.h>

#include <cmath>
#include <memory>

#include "commands.h"
#include "common/ray_gen.h"
#include "common/views.h"
#include "core/file_io.h"
#include "core/parallel.h"
#include "core/timer.h"
#include "core/vec.h"
#include "kestrel/error.h"
#include "kestrel/io.h"
#include "kestrel/parallel.h"

namespace kestrel::cli {

namespace {

struct PreviewArgs {
  std::string scene = "builtin:cornell_box", out = "preview.png", view, res = "512x512";
  BuildOptions build;
};

void run_preview(const PreviewArgs& a) {
  if (lower_extension(a.out) != ".png")
    throw Error(ErrorCode::invalid_argument,
                fmt::format("{}: preview writes a PNG, so its name must end in .png", a.out));
  const BuildConfig config = a.build.config();
  std::unique_ptr<ThreadLimit> limit;
  if (a.build.threads > 0) limit = std::make_unique<ThreadLimit>(a.build.threads);
  int w, h;
  parse_resolution(a.res, w, h);
  const Scene scene = load_scene_reporting(a.scene);
  std::string view = a.view;
  if (view.empty()) view = scene.source == "builtin:cornell_box" ? "front" : "framing";
  auto cam = tools::named_view(scene, view);
  if (!cam)
    throw Error(ErrorCode::invalid_argument, fmt::format("{}: no view named '{}'", a.scene, view));
  const Accel accel = build_accel(scene, config);
  if (accel.validation.report.valid_triangle_count == 0)
    throw Error(ErrorCode::invalid_geometry, fmt::format("{}: no valid triangle", a.scene));
  const std::vector<Triangle> tris = tools::scene_triangles(scene);  // to fetch hit normals
  std::vector<uint8_t> rgb(size_t(w) * h * 3);
  std::vector<float> depth(size_t(w) * h, INFINITY);
  std::vector<Vec3> normal(size_t(w) * h);
  Timer t;
  parallel_for(0, size_t(h), 4, [&](size_t y0, size_t y1) {
    for (size_t y = y0; y < y1; ++y)
      for (int x = 0; x < w; ++x) {
        const Ray ray = cam->ray(x, int(y), w, h);
        const Hit hit = intersect(accel, ray);
        if (!hit.hit()) continue;
        const Triangle& tri = tris[hit.prim_id];
        Vec3 n = normalize(cross(tri.v1 - tri.v0, tri.v2 - tri.v0));
        if (dot(n, ray.dir) > 0) n = -n;
        depth[y * w + x] = hit.t * length(ray.dir);
        normal[y * w + x] = n;
      }
  });
  const double trace_ms = t.ms();
  float dmin = INFINITY, dmax = 0;
  for (float d : depth)
    if (std::isfinite(d)) dmin = std::min(dmin, d), dmax = std::max(dmax, d);
  for (size_t i = 0; i < depth.size(); ++i) {
    Vec3 c{0.05f, 0.05f, 0.08f};
    if (std::isfinite(depth[i])) {
      // Normal as colour, darkened with distance.
      const float fade = dmax > dmin ? 1.0f - 0.6f * (depth[i] - dmin) / (dmax - dmin) : 1.0f;
      c = (normal[i] * 0.5f + Vec3{0.5f, 0.5f, 0.5f}) * fade;
    }
    rgb[3 * i] = uint8_t(std::clamp(c.x, 0.0f, 1.0f) * 255.0f + 0.5f);
    rgb[3 * i + 1] = uint8_t(std::clamp(c.y, 0.0f, 1.0f) * 255.0f + 0.5f);
    rgb[3 * i + 2] = uint8_t(std::clamp(c.z, 0.0f, 1.0f) * 255.0f + 0.5f);
  }
  write_png(a.out, w, h, rgb);
  fmt::print("scene    {} ({})\n", a.scene, accel.validation.report.summary());
  fmt::print("bvh      {}: {} bytes, built in {:.2f} ms\n",
             builder_name(resolve_builder(config, accel.prim_count)), accel.memory_bytes(),
             accel.build_ms);
  fmt::print("render   {}x{} in {:.2f} ms ({:.2f} Mrays/s)\n", w, h, trace_ms,
             double(w) * h / (trace_ms * 1e3));
  fmt::print("wrote    {}\n", a.out);
}

}  // namespace

Action add_preview_command(CLI::App& cmd) {
  auto args = std::make_shared<PreviewArgs>();
  cmd.add_option("scene", args->scene, "scene file or builtin:cornell_box (default)");
  cmd.add_option("-o,--out", args->out, "output PNG");
  cmd.add_option("--view", args->view,
                 "named view (framing; inside for Sponza; front for the built-in box)");
  cmd.add_option("--res", args->res, "WxH pixels");
  args->build.add_to(cmd);
  return [args] { run_preview(*args); };
}

}  // namespace kestrel::cli
