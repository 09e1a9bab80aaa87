// Build benchmark: builders x scenes, single thread by default, against Embree's LOW /
// MEDIUM / HIGH builds measured in the same run. Runs are interleaved (every builder and
// Embree quality once per round, rounds repeated) so drift in machine speed hits all
// columns alike; medians are reported. Prints a markdown table and writes JSON.
//
//   kestrel_build_bench [--scenes a.obj,b.gltf,...] [--repeat N] [--threads T] [--json F]
//                       [--markdown F] [--quick]
//
// Timed per kestrel builder:
//   bvh  = make_prim_refs + build_bvh (mesh to canonical Bvh2)
//   full = build_accel: validation + prim refs + BVH + collapse to the default wide layout,
//          i.e. everything rtcCommitScene does for Embree (its leaves hold triangles too).
#include <fmt/format.h>

#include <CLI/CLI.hpp>
#include <algorithm>
#include <filesystem>
#include <fstream>
#include <map>
#include <memory>

#include "core/timer.h"
#include "geometry/prim_ref.h"
#include "kestrel/kestrel.h"
#ifdef KESTREL_HAVE_EMBREE
#include "embree_peer.h"
#endif

namespace {

using namespace kestrel;

struct Row {
  std::string scene;
  size_t prims = 0;
  std::string name;  // builder or "embree-LOW", ...
  std::vector<double> bvh_ms, full_ms;
  double sah = 0, sah_unit = 0, bytes_per_prim = 0;
  bool valid = true;
};

std::vector<std::string> default_scenes(const std::string& root) {
  std::vector<std::string> out = {"builtin:cornell_box"};
  for (const char* s :
       {"teapot/teapot.obj", "dabrovic_sponza/sponza.obj", "stanford_bunny/stanford_bunny.obj",
        "lamborghini/lamborghini.obj", "bunny_grid/bunny_grid.obj"}) {
    const std::string p = root + "/" + s;
    if (std::filesystem::exists(p)) out.push_back(p);
  }
  return out;
}

std::string scene_label(const std::string& path) {
  if (path.rfind("builtin:", 0) == 0) return path;
  return std::filesystem::path(path).stem().string();
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"kestrel build benchmark (builders x scenes, Embree side by side)"};
  std::string scenes_arg, builders_arg, json_path = "build_bench.json", md_path;
  std::string scene_root = KESTREL_SCENE_ROOT;
  int repeat = 5, threads = 1;
  double max_seconds_per_cell = 20.0;
  bool quick = false;
  app.add_option("--scenes", scenes_arg,
                 "comma-separated scene files (default: the shared scenes)");
  app.add_option("--scene-root", scene_root, "folder of the shared scenes");
  app.add_option("--builders", builders_arg, "comma-separated kestrel builders (default: all)");
  app.add_option("--repeat", repeat, "rounds (median reported)")->check(CLI::Range(1, 100));
  app.add_option("--threads", threads,
                 "threads for kestrel and Embree (1 = single-thread figures)");
  app.add_option("--max-seconds", max_seconds_per_cell,
                 "stop repeating a cell after this much time");
  app.add_option("--json", json_path, "JSON output file");
  app.add_option("--markdown", md_path, "also write the markdown table here");
  app.add_flag("--quick", quick, "one round on the built-in Cornell box (smoke test)");
  CLI11_PARSE(app, argc, argv);

  std::vector<std::string> scenes;
  if (quick) {
    scenes = {"builtin:cornell_box"};
    repeat = 1;
  } else if (!scenes_arg.empty()) {
    std::stringstream ss(scenes_arg);
    for (std::string s; std::getline(ss, s, ',');) scenes.push_back(s);
  } else {
    scenes = default_scenes(scene_root);
  }
  std::vector<Builder> builders = {Builder::median, Builder::sweep,   Builder::binned,
                                   Builder::lbvh,   Builder::treelet, Builder::spatial};
  if (!builders_arg.empty()) {
    builders.clear();
    std::stringstream ss(builders_arg);
    for (std::string s; std::getline(ss, s, ',');) {
      auto b = builder_from_name(s);
      if (!b) {
        std::fprintf(stderr, "kestrel_build_bench: unknown builder '%s'\n", s.c_str());
        return 2;
      }
      builders.push_back(*b);
    }
  }
  ThreadLimit limit(threads);
  std::vector<Row> rows;
  try {
    for (const std::string& path : scenes) {
      const Scene scene = load_scene(path);
      const SceneValidation validation = validate_scene(scene);
      const size_t prims = validation.report.valid_triangle_count;
      std::map<std::string, Row> cells;
      std::map<std::string, double> spent;
#ifdef KESTREL_HAVE_EMBREE
      std::vector<std::unique_ptr<peer::EmbreeScene>> embree;
      for (auto q :
           {peer::EmbreeQuality::low, peer::EmbreeQuality::medium, peer::EmbreeQuality::high})
        embree.push_back(std::make_unique<peer::EmbreeScene>(scene, q, threads));
#endif
      for (int round = 0; round < repeat; ++round) {
        for (Builder b : builders) {
          Row& row = cells[builder_name(b)];
          if (spent[row.name = builder_name(b)] > max_seconds_per_cell && !row.bvh_ms.empty())
            continue;
          BuildConfig config;
          config.builder = b;
          Timer t0;
          Buffer<PrimRef> refs = make_prim_refs(scene, validation);
          // Spatial splits clip the triangles (gathered by id: part of its time).
          const Buffer<Triangle> triangles = triangles_for_builder(scene, validation, b);
          Bvh2 bvh = build_bvh(refs, triangles, config);
          row.bvh_ms.push_back(t0.ms());
          Timer t1;
          Accel accel = build_accel(scene, config);
          row.full_ms.push_back(t1.ms());
          spent[row.name] += (row.bvh_ms.back() + row.full_ms.back()) / 1000.0;
          if (round == 0) {
            const BvhMetrics m = compute_metrics(bvh, config);
            row.sah = m.sah_cost;
            row.sah_unit = m.sah_cost_unit;
            row.bytes_per_prim = prims ? double(accel.memory_bytes()) / double(prims) : 0;
            row.valid =
                validate_bvh(bvh, refs, config.max_leaf_size, b == Builder::spatial).empty();
          }
        }
#ifdef KESTREL_HAVE_EMBREE
        for (auto& e : embree) {
          const std::string name =
              std::string("embree-") +
              peer::embree_quality_name(e.get() == embree[0].get()   ? peer::EmbreeQuality::low
                                        : e.get() == embree[1].get() ? peer::EmbreeQuality::medium
                                                                     : peer::EmbreeQuality::high);
          Row& row = cells[name];
          row.name = name;
          if (spent[name] > max_seconds_per_cell && !row.full_ms.empty()) continue;
          const double ms = e->rebuild();
          row.full_ms.push_back(ms);
          spent[name] += ms / 1000.0;
          row.bytes_per_prim = prims ? double(e->memory_bytes()) / double(prims) : 0;
        }
#endif
      }
      for (auto& [name, row] : cells) {
        row.scene = scene_label(path);
        row.prims = prims;
        rows.push_back(row);
      }
    }
  } catch (const kestrel::Error& e) {
    std::fprintf(stderr, "kestrel_build_bench: %s\n", e.what());
    return 1;
  }

  // Table: one line per scene x builder; SAH ratio to sweep of the same scene.
  std::map<std::string, double> sweep_sah;
  for (const Row& r : rows)
    if (r.name == "sweep") sweep_sah[r.scene] = r.sah;
  std::string md = fmt::format(
      "| scene | prims | builder | bvh ms | full ms | full ms (min) | Mprims/s (full) | SAH | SAH "
      "/ sweep | SAH (Ct=Ci=1) | bytes/prim | valid |\n"
      "|---|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|---|\n");
  std::string json = "[\n";
  for (size_t i = 0; i < rows.size(); ++i) {
    const Row& r = rows[i];
    const double bvh = median(r.bvh_ms), full = median(r.full_ms);
    const double full_min =
        r.full_ms.empty() ? 0 : *std::min_element(r.full_ms.begin(), r.full_ms.end());
    const bool embree = r.name.rfind("embree", 0) == 0;
    const double ratio =
        sweep_sah.count(r.scene) && sweep_sah[r.scene] > 0 ? r.sah / sweep_sah[r.scene] : 0;
    md += fmt::format(
        "| {} | {} | {} | {} | {:.2f} | {:.2f} | {:.2f} | {} | {} | {} | {:.1f} | {} |\n", r.scene,
        r.prims, r.name, embree ? "-" : fmt::format("{:.2f}", bvh), full, full_min,
        full > 0 ? r.prims / (full * 1e3) : 0, embree ? "-" : fmt::format("{:.3f}", r.sah),
        embree ? "-" : fmt::format("{:.3f}", ratio),
        embree ? "-" : fmt::format("{:.3f}", r.sah_unit), r.bytes_per_prim,
        embree ? "-" : (r.valid ? "yes" : "NO"));
    json += fmt::format(
        "  {{\"scene\": \"{}\", \"prims\": {}, \"builder\": \"{}\", \"threads\": {}, \"runs\": {}, "
        "\"bvh_ms\": {:.4f}, "
        "\"full_ms\": {:.4f}, \"full_ms_min\": {:.4f}, \"sah\": {:.5f}, \"sah_over_sweep\": "
        "{:.5f}, \"sah_unit\": {:.5f}, \"bytes_per_prim\": {:.2f}, "
        "\"valid\": {}}}{}\n",
        r.scene, r.prims, r.name, threads, r.full_ms.size(), bvh, full, full_min, r.sah, ratio,
        r.sah_unit, r.bytes_per_prim, r.valid ? "true" : "false", i + 1 < rows.size() ? "," : "");
  }
  json += "]\n";
  fmt::print("{}", md);
  fmt::print("\nthreads {}, {} rounds (median); SAH constants Ct = {}, Ci = {}{}\n", threads,
             repeat, BuildConfig{}.traversal_cost, BuildConfig{}.intersection_cost,
#ifdef KESTREL_HAVE_EMBREE
             ", Embree " + peer::embree_version()
#else
             ", Embree not available"
#endif
  );
  std::ofstream(json_path) << json;
  if (!md_path.empty()) std::ofstream(md_path) << md;
  bool all_valid = true;
  for (const Row& r : rows) all_valid &= r.valid;
  return all_valid ? 0 : 1;
}
