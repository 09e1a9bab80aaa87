// Trace benchmark: kestrel against Embree on the same rays, in the same run, one thread.
//
// For each scene (the shared scenes, then the procedural soup, hairball, terrain and sphere
// field): primary rays from its view (the inside camera for Sponza), shadow rays
// (any hit) from the primary hits towards a point light, and diffuse bounce rays. Each ray
// set is traced by kestrel (the library's default choice, and optionally every layout x ISA)
// and by Embree (rtcIntersect1 / rtcOccluded1, and rtcIntersect16 for packets), runs
// alternating A B A B after untimed warm-up calls (--warmup for kestrel, whose Accel learns
// which way to trace in its first batches; one for Embree); medians of Mrays/s, the ratio,
// and how many hits agree.
// With --amortization, also the build-vs-trace curve (see docs/benchmarks.md).
//
//   kestrel_trace_bench [--scenes a.obj,...] [--res 1280x720] [--repeat 5] [--warmup 4]
//                       [--all-kernels]
//                       [--builder B] [--peer-quality low|medium|high]
//                       [--json F] [--markdown F] [--amortization F.csv] [--quick]
#include <fmt/format.h>

#include <CLI/CLI.hpp>
#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <memory>
#include <optional>
#include <random>
#include <sstream>

#include "common/ray_gen.h"
#include "common/views.h"
#include "core/timer.h"
#include "kestrel/kestrel.h"
#ifdef KESTREL_HAVE_EMBREE
#include "bvh/cost_model.h"
#include "embree_peer.h"
#endif

namespace {

using namespace kestrel;

struct SceneSpec {
  std::string path, view;
};

std::string label(const std::string& path) {
  if (path.rfind("builtin:", 0) == 0) return path.substr(8);
  return std::filesystem::path(path).stem().string();
}

std::vector<SceneSpec> default_scenes(const std::string& root) {
  std::vector<SceneSpec> out;
  for (auto [rel, view] : {std::pair{"dabrovic_sponza/sponza.obj", "inside"},
                           {"lamborghini/lamborghini.obj", "framing"},
                           {"bunny_grid/bunny_grid.obj", "framing"},
                           {"teapot/teapot.obj", "framing"},
                           {"cornell_box/cornell_box.obj", "framing"}}) {
    const std::string p = root + "/" + rel;
    if (std::filesystem::exists(p)) out.push_back({p, view});
  }
  if (out.empty()) out.push_back({"builtin:cornell_box", "front"});
  // Geometry the shared scenes lack, generated (src/io/procedural_scenes.cpp).
  for (auto [name, view] : {std::pair{"soup", "framing"},
                            {"hairball", "framing"},
                            {"terrain", "low"},
                            {"sphere_field", "low"}})
    out.push_back({std::string("builtin:") + name, view});
  return out;
}

// "path[:view]", "builtin:NAME[:view]"; without a view: "front" where the scene has one,
// else "framing".
SceneSpec parse_scene_spec(const std::string& s) {
  const bool builtin = s.rfind("builtin:", 0) == 0;
  const size_t colon = s.rfind(':');
  if (colon != std::string::npos && (builtin ? colon > 7 : colon > 1))
    return {s.substr(0, colon), s.substr(colon + 1)};
  return {s, ""};
}

struct Result {
  std::string scene, kind, kestrel_variant, peer;
  size_t rays = 0;
  double kestrel_mrays = 0, peer_mrays = 0;
  double agree = 1;  // fraction of rays with the same answer (closest: same prim or same t)
};

// Same answer: same prim, or (ties at shared edges / duplicates) the same distance.
bool same_hit(const Hit& a, const Hit& b) {
  if (a.prim_id == b.prim_id) return true;
  if (!a.hit() || !b.hit()) return false;
  return std::fabs(a.t - b.t) <= 1e-4f * std::max(1.0f, std::fabs(a.t));
}

struct Variant {
  std::string name;
  Layout layout;
  TraceOptions options;
};

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"kestrel trace benchmark: kestrel vs Embree on the same rays, one thread"};
  std::string builder_arg, peer_quality = "medium";
  float ci = 1.0f;
  uint32_t max_leaf = 8;
  std::string scenes_arg, json_path = "trace_bench.json", md_path, amort_path, res = "1280x720";
  std::string scene_root = KESTREL_SCENE_ROOT;
  int repeat = 5, warmup_calls = 4;
  bool quick = false, all_kernels = false;
  app.add_option("--scenes", scenes_arg,
                 "comma-separated scene files (path[:view]); default: the shared scenes");
  app.add_option("--scene-root", scene_root, "folder of the shared scenes");
  app.add_option("--res", res, "primary ray resolution WxH");
  app.add_option("--repeat", repeat, "rounds, alternating kestrel and Embree (median reported)")
      ->check(CLI::Range(1, 100));
  app.add_option("--warmup", warmup_calls,
                 "untimed kestrel calls per ray set before the timed rounds (its timed choices "
                 "settle in the first four)")
      ->check(CLI::Range(0, 100));
  app.add_option("--builder", builder_arg,
                 "kestrel builder for the trace runs (default: the library's default)");
  app.add_option(
         "--peer-quality", peer_quality,
         "Embree's build quality: low, medium (default) or high (against --builder spatial)")
      ->check(CLI::IsMember({"low", "medium", "high"}));
  app.add_option("--ci", ci, "intersection cost Ci of the SAH (Ct = 1)");
  app.add_option("--max-leaf", max_leaf, "max primitives per leaf");
  app.add_flag("--all-kernels", all_kernels, "also every layout x ISA, not only the default");
  app.add_option("--json", json_path, "JSON output file");
  app.add_option("--markdown", md_path, "also write the markdown table here");
  app.add_option("--amortization", amort_path, "write the build-vs-trace curve as CSV here");
  app.add_flag("--quick", quick, "one round, small image, the Cornell box (smoke test)");
  CLI11_PARSE(app, argc, argv);

  int width = 0, height = 0;
  if (std::sscanf(res.c_str(), "%dx%d", &width, &height) != 2 || width <= 0 || height <= 0) {
    std::fprintf(stderr, "kestrel_trace_bench: bad --res '%s'\n", res.c_str());
    return 2;
  }
  std::vector<SceneSpec> scenes;
  if (quick) {
    scenes = {{"builtin:cornell_box", "front"}};
    repeat = 1, warmup_calls = 1;
    width = 160, height = 90;
  } else if (!scenes_arg.empty()) {
    std::stringstream ss(scenes_arg);
    for (std::string s; std::getline(ss, s, ',');) scenes.push_back(parse_scene_spec(s));
  } else {
    scenes = default_scenes(scene_root);
  }

  ThreadLimit one_thread(1);
  std::vector<Variant> variants = {{"default", Layout::automatic, {}}};
  if (all_kernels) {
    for (Layout layout : {Layout::bvh4, Layout::bvh8})
      for (Isa isa : {Isa::sse2, Isa::avx2, Isa::avx512})
        if (isa_supported(isa))
          variants.push_back({fmt::format("{}-{}", layout_name(layout), isa_name(isa)),
                              layout,
                              {isa, false, std::nullopt}});
    variants.push_back({"bvh2-scalar", Layout::bvh2, {}});
  }
  std::vector<Result> results;
  struct MemRow {
    std::string scene;
    size_t prims;
    double kestrel_bpp, embree_bpp;
  };
  std::vector<MemRow> memory;
  struct AutoRow {
    std::string scene;
    double rays;
    std::string pick, best;
    double pick_mrays, best_mrays;
  };
  std::vector<AutoRow> auto_rows;
  std::ofstream amort;
  if (!amort_path.empty()) {
    amort.open(amort_path);
    amort << "scene,method,prims,build_ms,mrays_per_s,rays_per_build,effective_mrays_per_s,note\n";
  }
  try {
    for (const SceneSpec& spec : scenes) {
      const Scene scene = load_scene(spec.path);
      const std::string name = label(spec.path);
      auto cam = spec.view.empty() ? tools::named_view(scene, "front")
                                   : tools::named_view(scene, spec.view);
      if (!cam && spec.view.empty()) cam = tools::named_view(scene, "framing");
      if (!cam)
        throw Error(ErrorCode::invalid_argument,
                    fmt::format("{}: no view named '{}'", spec.path, spec.view));
      // Accels: one per layout variant (built once; build time is the build benchmark's).
      std::vector<Accel> accels;
      for (const Variant& v : variants) {
        BuildConfig c;
        c.layout = v.layout;
        c.intersection_cost = ci;
        c.max_leaf_size = max_leaf;
        if (!builder_arg.empty()) c.builder = builder_from_name(builder_arg);
        accels.push_back(build_accel(scene, c));
      }
      const Accel& accel = accels[0];
      const std::vector<Ray> primary = tools::primary_rays(*cam, width, height);
      const Vec3 light = tools::default_light(tools::scene_bounds(scene));
      const std::vector<Ray> shadow =
          tools::secondary_rays(accel, scene, primary, tools::RayKind::shadow, light, 7);
      const std::vector<Ray> diffuse =
          tools::secondary_rays(accel, scene, primary, tools::RayKind::diffuse, light, 7);
#ifdef KESTREL_HAVE_EMBREE
      peer::EmbreeScene embree(scene,
                               peer_quality == "low"    ? peer::EmbreeQuality::low
                               : peer_quality == "high" ? peer::EmbreeQuality::high
                                                        : peer::EmbreeQuality::medium,
                               1);
      memory.push_back(
          {name, accel.prim_count,
           double(accel.memory_bytes()) / double(std::max<size_t>(1, accel.prim_count)),
           double(embree.memory_bytes()) / double(std::max<size_t>(1, accel.prim_count))});
#else
      memory.push_back(
          {name, accel.prim_count,
           double(accel.memory_bytes()) / double(std::max<size_t>(1, accel.prim_count)), 0});
#endif
      // The diffuse rays again in a random order (a renderer's rays after compaction or
      // sorting by material): what the stream mode is for; and any hit along them.
      std::vector<Ray> shuffled = diffuse;
      std::shuffle(shuffled.begin(), shuffled.end(), std::mt19937(11));
      struct Kind {
        const char* name;
        const std::vector<Ray>* rays;
        bool any_hit, packets;
        std::optional<bool> stream = {};
      };
      // The library's default takes the stream for the diffuse sets (>= 16 k incoherent
      // rays); the "-nostream" rows trace the same rays in the caller's order.
      const Kind kinds[] = {{"primary", &primary, false, false},
                            {"shadow", &shadow, true, false},
                            {"diffuse", &diffuse, false, false},
                            {"diffuse-nostream", &diffuse, false, false, false},
                            {"diffuse-shuffled", &shuffled, false, false},
                            {"shuffled-nostream", &shuffled, false, false, false},
                            {"diffuse-any", &diffuse, true, false},
                            {"any-nostream", &diffuse, true, false, false},
                            {"primary-packets", &primary, false, true}};
      for (const Kind& kind : kinds) {
        const std::vector<Ray>& rays = *kind.rays;
        if (rays.empty()) continue;
        std::vector<Hit> ours(rays.size()), theirs(rays.size());
        std::vector<uint8_t> occ(rays.size());
        for (size_t vi = 0; vi < variants.size(); ++vi) {
          if (kind.packets && variants[vi].layout == Layout::bvh2) continue;
          TraceOptions opt = variants[vi].options;
          if (kind.packets) opt.packets = true;
          if (kind.stream) opt.stream = kind.stream;
#ifdef KESTREL_HAVE_EMBREE
          const auto peer = [&] {
            if (kind.any_hit)
              embree.occluded(rays, occ);
            else if (kind.packets)
              embree.intersect16(rays, theirs);
            else
              embree.intersect(rays, theirs);
          };
#endif
          // Untimed first: kestrel's Accel times some batches each way while it learns which
          // way is faster (packets or single rays, ray streams or not; stream.h's
          // PacketChoice: the first four whole batches alternate), so the timed rounds see the
          // choice a renderer's steady state makes; Embree's first call warms its caches.
          for (int w = 0; w < warmup_calls; ++w) trace(accels[vi], rays, ours, kind.any_hit, opt);
#ifdef KESTREL_HAVE_EMBREE
          if (vi == 0) peer();
#endif
          std::vector<double> a_ms, b_ms;
          for (int r = 0; r < repeat; ++r) {
            Timer ta;
            trace(accels[vi], rays, ours, kind.any_hit, opt);
            a_ms.push_back(ta.ms());
#ifdef KESTREL_HAVE_EMBREE
            if (vi == 0) {
              Timer tb;
              peer();
              b_ms.push_back(tb.ms());
            }
#endif
          }
          Result res;
          res.scene = name;
          res.kind = kind.name;
          res.kestrel_variant = variants[vi].name;
          res.rays = rays.size();
          res.kestrel_mrays = double(rays.size()) / (median(a_ms) * 1e3);
          if (!b_ms.empty()) {
            res.peer = kind.packets   ? "rtcIntersect16"
                       : kind.any_hit ? "rtcOccluded1"
                                      : "rtcIntersect1";
            if (peer_quality != "medium") res.peer += " " + peer_quality;
            res.peer_mrays = double(rays.size()) / (median(b_ms) * 1e3);
            size_t same = 0;
            for (size_t i = 0; i < rays.size(); ++i)
              same += kind.any_hit ? ours[i].hit() == bool(occ[i]) : same_hit(ours[i], theirs[i]);
            res.agree = double(same) / double(rays.size());
          }
          results.push_back(res);
          fmt::print("{:<12} {:<16} {:<14} {:>8} rays  kestrel {:7.2f} Mrays/s", name, kind.name,
                     res.kestrel_variant, rays.size(), res.kestrel_mrays);
          if (res.peer_mrays > 0)
            fmt::print("  Embree {:7.2f}  ratio {:5.2f}  agree {:.4f}%", res.peer_mrays,
                       res.kestrel_mrays / res.peer_mrays, 100 * res.agree);
          fmt::print("\n");
          std::fflush(stdout);
        }
      }

      // The amortization curve: per builder, full build time (one thread) and the trace
      // speed of a mixed workload (primary + diffuse rays, the render loop's mix).
      if (amort.is_open()) {
        std::vector<Ray> mix = primary;
        mix.insert(mix.end(), diffuse.begin(), diffuse.end());
        std::vector<Hit> hits(mix.size());
        struct Point {
          std::string method;
          double build_ms, mrays;
        };
        // Rounds are interleaved across all methods (machine speed drifts between runs).
        const std::vector<Builder> builders = {Builder::median, Builder::lbvh,    Builder::binned,
                                               Builder::sweep,  Builder::spatial, Builder::treelet};
        std::vector<std::string> names;
        for (Builder bld : builders) names.push_back(builder_name(bld));
#ifdef KESTREL_HAVE_EMBREE
        std::vector<std::unique_ptr<peer::EmbreeScene>> peers;
        for (auto q :
             {peer::EmbreeQuality::low, peer::EmbreeQuality::medium, peer::EmbreeQuality::high}) {
          peers.push_back(std::make_unique<peer::EmbreeScene>(scene, q, 1));
          names.push_back(std::string("embree-") + peer::embree_quality_name(q));
        }
#endif
        std::vector<std::vector<double>> build_ms(names.size()), trace_ms(names.size());
        for (int r = 0; r < std::max(3, repeat); ++r) {
          for (size_t m = 0; m < names.size(); ++m) {
            if (m < builders.size()) {
              BuildConfig c;
              c.builder = builders[m];
              Accel a = build_accel(scene, c);
              build_ms[m].push_back(a.build_ms);
              Timer t;
              trace(a, mix, hits);
              trace_ms[m].push_back(t.ms());
            }
#ifdef KESTREL_HAVE_EMBREE
            else {
              peer::EmbreeScene& e = *peers[m - builders.size()];
              build_ms[m].push_back(e.rebuild());
              Timer t;
              e.intersect(mix, hits);
              trace_ms[m].push_back(t.ms());
            }
#endif
          }
        }
        std::vector<Point> points;
        for (size_t m = 0; m < names.size(); ++m)
          points.push_back(
              {names[m], median(build_ms[m]), double(mix.size()) / (median(trace_ms[m]) * 1e3)});
        auto effective = [](const Point& p, double R) {
          return R / (p.build_ms * 1e-3 + R / (p.mrays * 1e6)) * 1e-6;
        };
        for (const Point& p : points) {
          fmt::print("{:<12} amortization {:<14} build {:9.2f} ms  trace {:7.2f} Mrays/s\n", name,
                     p.method, p.build_ms, p.mrays);
          for (double lg = 4; lg <= 10.0001; lg += 0.25) {
            const double R = std::pow(10.0, lg);
            amort << fmt::format("{},{},{},{:.4f},{:.4f},{:.6g},{:.6f},\n", name, p.method,
                                 accel.prim_count, p.build_ms, p.mrays, R, effective(p, R));
          }
        }
        // quality = auto: the builder the cost model picks for R, at its measured throughput,
        // against the best fixed kestrel builder at that R.
        for (double lg = 4; lg <= 10.0001; lg += 0.25) {
          const double R = std::pow(10.0, lg);
          const std::string pick = builder_name(choose_builder(accel.prim_count, R));
          double best = 0, chosen = 0;
          std::string best_name;
          const Point* picked = nullptr;
          for (const Point& p : points) {
            if (p.method.rfind("embree", 0) == 0) continue;
            const double e = effective(p, R);
            if (e > best) best = e, best_name = p.method;
            if (p.method == pick) chosen = e, picked = &p;
          }
          amort << fmt::format("{},auto,{},{:.4f},{:.4f},{:.6g},{:.6f},picks {} (best fixed: {})\n",
                               name, accel.prim_count, picked ? picked->build_ms : 0.0,
                               picked ? picked->mrays : 0.0, R, chosen, pick, best_name);
          auto_rows.push_back({name, R, pick, best_name, chosen, best});
        }
      }
    }
  } catch (const std::exception& e) {
    std::fprintf(stderr, "kestrel_trace_bench: %s\n", e.what());
    return 1;
  }

  // Markdown table and JSON.
  std::string md = fmt::format(
      "Single thread, same rays, runs alternating kestrel / Embree, median of {} (Mrays/s).\n\n",
      repeat);
  md +=
      "| scene | rays | kestrel | rays | kestrel Mrays/s | Embree call | Embree Mrays/s | ratio | "
      "same hits |\n";
  md += "|---|---|---|---:|---:|---|---:|---:|---:|\n";
  for (const Result& r : results)
    md +=
        fmt::format("| {} | {} | {} | {} | {:.2f} | {} | {} | {} | {} |\n", r.scene, r.kind,
                    r.kestrel_variant, r.rays, r.kestrel_mrays, r.peer.empty() ? "-" : r.peer,
                    r.peer_mrays > 0 ? fmt::format("{:.2f}", r.peer_mrays) : "-",
                    r.peer_mrays > 0 ? fmt::format("{:.2f}", r.kestrel_mrays / r.peer_mrays) : "-",
                    r.peer_mrays > 0 ? fmt::format("{:.3f}%", 100 * r.agree) : "-");
  md += "\n| scene | triangles | kestrel bytes/prim | Embree bytes/prim |\n|---|---:|---:|---:|\n";
  for (const MemRow& m : memory)
    md += fmt::format("| {} | {} | {:.1f} | {:.1f} |\n", m.scene, m.prims, m.kestrel_bpp,
                      m.embree_bpp);
  if (!auto_rows.empty()) {
    md +=
        "\n`quality = auto` against the best fixed kestrel builder (effective Mrays/s at R rays "
        "per build):\n\n";
    md +=
        "| scene | R | auto picks | its effective Mrays/s | best fixed | best Mrays/s | auto / "
        "best |\n|---|---:|---|---:|---|---:|---:|\n";
    for (const AutoRow& a : auto_rows) {
      const double lg = std::log10(a.rays);
      if (std::fabs(lg - std::round(lg)) > 1e-6) continue;  // decades only in the table
      md += fmt::format("| {} | 1e{:.0f} | {} | {:.3f} | {} | {:.3f} | {:.3f} |\n", a.scene, lg,
                        a.pick, a.pick_mrays, a.best, a.best_mrays,
                        a.best_mrays > 0 ? a.pick_mrays / a.best_mrays : 0.0);
    }
  }
  fmt::print("\n{}", md);
  if (!md_path.empty()) std::ofstream(md_path) << md;
  std::ofstream json(json_path);
  json << "{\n  \"isa\": \"" << isa_name(default_isa()) << "\",\n  \"repeat\": " << repeat
       << ",\n  \"results\": [\n";
  for (size_t i = 0; i < results.size(); ++i) {
    const Result& r = results[i];
    json << fmt::format(
        "    {{\"scene\": \"{}\", \"kind\": \"{}\", \"kestrel\": \"{}\", \"rays\": {}, "
        "\"kestrel_mrays\": {:.4f}, "
        "\"peer\": \"{}\", \"peer_mrays\": {:.4f}, \"agree\": {:.6f}}}{}\n",
        r.scene, r.kind, r.kestrel_variant, r.rays, r.kestrel_mrays, r.peer, r.peer_mrays, r.agree,
        i + 1 < results.size() ? "," : "");
  }
  json << "  ],\n  \"memory\": [\n";
  for (size_t i = 0; i < memory.size(); ++i)
    json << fmt::format(
        "    {{\"scene\": \"{}\", \"prims\": {}, \"kestrel_bytes_per_prim\": {:.3f}, "
        "\"embree_bytes_per_prim\": {:.3f}}}{}\n",
        memory[i].scene, memory[i].prims, memory[i].kestrel_bpp, memory[i].embree_bpp,
        i + 1 < memory.size() ? "," : "");
  json << "  ]\n}\n";
  return 0;
}
