// `kestrel bvh`: build time (median of repeated builds) and every quality metric.
#include <fmt/format.h>

#include <algorithm>
#include <memory>
#include <string_view>

#include "commands.h"
#include "core/timer.h"
#include "distributed/distributed.h"
#include "geometry/prim_ref.h"
#include "kestrel/error.h"
#include "kestrel/parallel.h"
#include "kestrel/scene.h"
#include "traverse/accel_nodes.h"
#include "traverse/wide_bvh.h"

namespace kestrel::cli {

void BuildOptions::add_to(CLI::App& cmd) {
  cmd.add_option(
      "--builder", builder,
      "median | sweep | binned | lbvh | spatial | treelet (overrides --quality). spatial "
      "= binned SAH with spatial splits (Stich et al. 2009). treelet = Karras & Aila "
      "2013 treelet restructuring, covered by NVIDIA patents (US 10331632); never a "
      "default");
  cmd.add_option(
      "--quality", quality,
      "fast (lbvh) | balanced (binned) | high (spatial) | auto (best for --expected-rays per "
      "build)");
  cmd.add_option("--expected-rays", expected_rays, "rays traced per build, for --quality auto");
  cmd.add_option("--threads", threads, "worker threads (0 = all)")->check(CLI::Range(0, 1024));
  cmd.add_option("--traversal-cost", traversal_cost, "SAH Ct, cost of an inner node visit");
  cmd.add_option("--intersection-cost", intersection_cost, "SAH Ci, cost of a triangle test");
  cmd.add_option("--max-leaf-size", max_leaf_size, "primitives per leaf, at most");
  cmd.add_option("--bins", bin_count, "binned SAH bins per axis at the top levels (8..32)");
  cmd.add_option("--morton-bits", morton_bits, "lbvh/treelet Morton code bits (30 or 63)");
}

BuildConfig BuildOptions::config() const {
  BuildConfig c;
  if (!builder.empty()) {
    c.builder = builder_from_name(builder);
    if (!c.builder)
      throw Error(
          ErrorCode::invalid_argument,
          fmt::format("unknown builder '{}' (median, sweep, binned, lbvh, spatial, treelet)",
                      builder));
  }
  auto q = quality_from_name(quality);
  if (!q)
    throw Error(ErrorCode::invalid_argument,
                fmt::format("unknown quality '{}' (fast, balanced, high, auto)", quality));
  c.quality = *q;
  c.expected_rays = expected_rays;
  c.traversal_cost = traversal_cost;
  c.intersection_cost = intersection_cost;
  c.max_leaf_size = max_leaf_size;
  c.bin_count = bin_count;
  c.morton_bits = morton_bits;
  check_build_config(c);
  return c;
}

Scene load_scene_reporting(const std::string& path) {
  Scene scene = load_scene(path);
  if (distributed::rank() == 0)  // one copy under mpirun
    for (const std::string& w : scene.warnings) fmt::print(stderr, "kestrel: warning: {}\n", w);
  return scene;
}

Asset load_asset_reporting(const std::string& path) {
  Asset asset = Asset::load(path);
  if (distributed::rank() == 0)
    for (const std::string& w : asset.warnings()) fmt::print(stderr, "kestrel: warning: {}\n", w);
  return asset;
}

void parse_resolution(const std::string& text, int& width, int& height) {
  // Strictly WxH: digits, 'x', digits, nothing else ("16x16junk" and "+16x-4" are errors).
  const size_t x = text.find('x');
  auto number = [](std::string_view s, int& v) {
    if (s.empty() || s.size() > 6 ||
        !std::all_of(s.begin(), s.end(), [](char c) { return c >= '0' && c <= '9'; }))
      return false;
    v = std::stoi(std::string(s));
    return true;
  };
  if (x == std::string::npos || !number(std::string_view(text).substr(0, x), width) ||
      !number(std::string_view(text).substr(x + 1), height) || width <= 0 || height <= 0 ||
      width > 32768 || height > 32768)
    throw Error(
        ErrorCode::invalid_argument,
        fmt::format("resolution '{}' is not WxH with sizes from 1 to 32768 (e.g. 1280x720)", text));
}

namespace {

struct BvhArgs {
  std::string scene;
  BuildOptions build;
  int repeat = 5;
  bool json = false;
};

void run_bvh(const BvhArgs& a) {
  const BuildConfig config = a.build.config();
  std::unique_ptr<ThreadLimit> limit;
  if (a.build.threads > 0) limit = std::make_unique<ThreadLimit>(a.build.threads);
  Timer load_timer;
  const Scene scene = load_scene_reporting(a.scene);
  const double load_ms = load_timer.ms();
  const SceneValidation validation = validate_scene(scene);
  if (validation.report.valid_triangle_count == 0)
    throw Error(ErrorCode::invalid_geometry,
                fmt::format("{}: no valid triangle ({})", a.scene, validation.report.summary()));
  std::vector<double> ref_ms, build_ms;
  Buffer<PrimRef> refs;
  Bvh2 bvh;
  const Builder builder = resolve_builder(config, validation.report.valid_triangle_count);
  const bool spatial = builder == Builder::spatial;
  const Buffer<Triangle> triangles = triangles_for_builder(scene, validation, builder);
  for (int r = 0; r < std::max(1, a.repeat); ++r) {
    Timer t0;
    refs = make_prim_refs(scene, validation);
    ref_ms.push_back(t0.ms());
    Timer t1;
    bvh = build_bvh(refs, triangles, config);  // spatial splits clip the triangles
    build_ms.push_back(t1.ms());
  }
  // Ready to trace: what trace and the renderer build (validation, prim refs, the tree, the
  // collapse to the traced layout and its triangle blocks), timed the same way.
  std::vector<double> accel_ms;
  std::string accel_layout;
  double accel_sah = 0;  // the traced tree's own SAH cost (wide layouts; lbvh's is built directly)
  for (int r = 0; r < std::max(1, a.repeat); ++r) {
    Timer t;
    const Accel accel = build_accel(scene, config);
    accel_ms.push_back(t.ms());
    accel_layout = layout_name(accel.layout);
    if (r + 1 < std::max(1, a.repeat)) continue;  // every build is the same tree: cost it once
    if (accel.layout == Layout::bvh8) accel_sah = wide_sah_cost(accel.nodes->bvh8);
    if (accel.layout == Layout::bvh4) accel_sah = wide_sah_cost(accel.nodes->bvh4);
  }
  const BvhMetrics m = compute_metrics(bvh, config);
  const std::string problem = validate_bvh(bvh, refs, config.max_leaf_size, spatial);
  const double med = median(build_ms);
  const char* name = builder_name(builder);
  if (a.json) {
    std::string hist;
    for (size_t k = 1; k < m.leaf_size_histogram.size(); ++k)
      hist += fmt::format("{}{}", k > 1 ? ", " : "", m.leaf_size_histogram[k]);
    fmt::print(
        "{{\"scene\": \"{}\", \"builder\": \"{}\", \"threads\": {}, \"triangles\": {}, "
        "\"valid_triangles\": {}, "
        "\"load_ms\": {:.3f}, \"prim_refs_ms\": {:.3f}, \"build_ms\": {:.3f}, \"build_runs\": {}, "
        "\"accel_build_ms\": {:.3f}, \"accel_layout\": \"{}\", \"accel_sah_cost\": {:.5f}, "
        "\"mprims_per_s\": {:.3f}, "
        "\"sah_cost\": {:.5f}, \"sah_cost_unit\": {:.5f}, \"traversal_cost\": {}, "
        "\"intersection_cost\": {}, "
        "\"leaf_references\": {}, "
        "\"nodes\": {}, \"inner_nodes\": {}, \"leaves\": {}, \"max_depth\": {}, "
        "\"mean_leaf_depth\": {:.3f}, "
        "\"leaf_size_histogram\": [{}], \"bytes_per_prim\": {:.3f}, \"valid\": {}, \"problem\": "
        "\"{}\"}}\n",
        a.scene, name, a.build.threads, validation.report.triangle_count,
        validation.report.valid_triangle_count, load_ms, median(ref_ms), med, build_ms.size(),
        median(accel_ms), accel_layout, accel_sah, double(refs.size()) / (med * 1e3), m.sah_cost,
        m.sah_cost_unit, config.traversal_cost, config.intersection_cost, bvh.prim_ids.size(),
        m.node_count, m.inner_count, m.leaf_count, m.max_depth, m.mean_leaf_depth, hist,
        m.bytes_per_prim, problem.empty() ? "true" : "false", problem);
  } else {
    fmt::print("scene          {}\n", a.scene);
    fmt::print("validation     {}\n", validation.report.summary());
    fmt::print("builder        {} (threads: {})\n", name,
               a.build.threads > 0 ? a.build.threads : hardware_thread_count());
    fmt::print("load           {:.1f} ms\n", load_ms);
    fmt::print("prim refs      {:.2f} ms (median)\n", median(ref_ms));
    fmt::print("build          {:.2f} ms (median of {}), {:.2f} Mprims/s\n", med, build_ms.size(),
               double(refs.size()) / (med * 1e3));
    fmt::print(
        "ready to trace {:.2f} ms (median of {}; {} layout: validation, prim refs, tree, "
        "collapse, triangles)\n",
        median(accel_ms), accel_ms.size(), accel_layout);
    if (accel_sah > 0)
      fmt::print("traced tree    SAH cost {:.4f} (wide: a slot test costs 1, a leaf block 1)\n",
                 accel_sah);
    fmt::print("SAH cost       {:.4f} (Ct = {}, Ci = {}); {:.4f} with Ct = Ci = 1\n", m.sah_cost,
               config.traversal_cost, config.intersection_cost, m.sah_cost_unit);
    fmt::print("nodes          {} ({} inner, {} leaves)\n", m.node_count, m.inner_count,
               m.leaf_count);
    if (bvh.prim_ids.size() != refs.size())  // spatial splits
      fmt::print("references     {} in leaves for {} triangles (+{:.1f} %)\n", bvh.prim_ids.size(),
                 refs.size(), 100.0 * (double(bvh.prim_ids.size()) / double(refs.size()) - 1.0));
    fmt::print("depth          max {}, mean leaf {:.2f}\n", m.max_depth, m.mean_leaf_depth);
    fmt::print("leaf sizes     ");
    for (size_t k = 1; k < m.leaf_size_histogram.size(); ++k)
      if (m.leaf_size_histogram[k]) fmt::print("{}:{} ", k, m.leaf_size_histogram[k]);
    fmt::print("\nbytes/prim     {:.2f} (nodes + prim ids; triangles add 36)\n", m.bytes_per_prim);
    fmt::print("validate       {}\n", problem.empty() ? "ok" : problem);
  }
  if (!problem.empty())
    throw Error(ErrorCode::invalid_geometry, "BVH failed validation: " + problem);
}

}  // namespace

Action add_bvh_command(CLI::App& cmd) {
  auto args = std::make_shared<BvhArgs>();
  cmd.add_option("scene", args->scene, "scene file (.obj, .gltf, .glb) or builtin:cornell_box")
      ->required();
  args->build.add_to(cmd);
  cmd.add_option("--repeat", args->repeat, "builds to time (the median is reported)")
      ->check(CLI::Range(1, 1000));
  cmd.add_flag("--json", args->json, "print one JSON object");
  return [args] { run_bvh(*args); };
}

}  // namespace kestrel::cli
