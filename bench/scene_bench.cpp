// Two-level scene benchmark: per-frame update costs and the two-level trace penalty.
//
//  1. Bunny grid as 16 instances of one bunny BLAS (+ its ground quad) against the same
//     scene flattened into one BVH (bunny_grid.obj): trace Mrays/s of primary and diffuse
//     rays, runs alternating, one thread, and the ratio.
//  2. Moving instances: N instances (--instances 10000,100000,1000000) of a few meshes on a
//     grid, every instance moving every frame: per frame the TLAS rebuild ms and the trace
//     Mrays/s of primary rays.
//  3. The animated glTF scenes (node animations, morph targets): per frame the pose, TLAS,
//     BLAS refit / rebuild ms and trace Mrays/s.
//  4. A deforming mesh (the Lamborghini, all parts as one mesh, a travelling wave): per frame
//     BLAS refit (or rebuild, when the SAH cost degrades past the threshold) ms, alternating
//     with Embree's rtcCommitScene of the same vertices under RTC_BUILD_QUALITY_REFIT.
// Medians over frames; one thread.
//
//   kestrel_scene_bench [--frames 10] [--instances 10000,100000,1000000] [--quick] [--json F]
#include <fmt/format.h>

#include <CLI/CLI.hpp>
#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <random>
#include <sstream>

#include "common/ray_gen.h"
#include "common/views.h"
#include "core/timer.h"
#include "kestrel/kestrel.h"
#ifdef KESTREL_HAVE_EMBREE
#include "embree_peer.h"
#endif

namespace {

using namespace kestrel;

TriangleMesh merge(const Scene& s) {
  TriangleMesh out;
  for (const TriangleMesh& m : s.meshes) {
    const uint32_t base = uint32_t(out.positions.size());
    out.positions.insert(out.positions.end(), m.positions.begin(), m.positions.end());
    for (uint32_t i : m.indices) out.indices.push_back(base + i);
  }
  return out;
}

TriangleMesh sphere_mesh(int rings, int segments, float r) {
  TriangleMesh m;
  for (int i = 0; i <= rings; ++i)
    for (int j = 0; j < segments; ++j) {
      const float th = 3.14159265f * float(i) / float(rings),
                  ph = 6.2831853f * float(j) / float(segments);
      m.positions.push_back(
          {r * std::sin(th) * std::cos(ph), r * std::cos(th), r * std::sin(th) * std::sin(ph)});
    }
  for (int i = 0; i < rings; ++i)
    for (int j = 0; j < segments; ++j) {
      const uint32_t a = uint32_t(i * segments + j),
                     b = uint32_t(i * segments + (j + 1) % segments);
      const uint32_t c = a + uint32_t(segments), d = b + uint32_t(segments);
      m.indices.insert(m.indices.end(), {a, c, b, b, c, d});
    }
  return m;
}

TriangleMesh box_mesh(float h) {
  TriangleMesh m;
  for (int i = 0; i < 8; ++i)
    m.positions.push_back({i & 1 ? h : -h, i & 2 ? h : -h, i & 4 ? h : -h});
  m.indices = {0, 2, 1, 1, 2, 3, 4, 5, 6, 5, 7, 6, 0, 1, 4, 1, 5, 4,
               2, 6, 3, 3, 6, 7, 0, 4, 2, 2, 4, 6, 1, 3, 5, 3, 7, 5};
  return m;
}

struct Json {
  std::string body;
  void add(const std::string& row) { body += (body.empty() ? "    " : ",\n    ") + row; }
};

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"kestrel two-level scene benchmark: per-frame updates and the instancing penalty"};
  std::string scene_root = KESTREL_SCENE_ROOT, counts = "10000,100000,1000000",
              json_path = "scene_bench.json", res = "640x360";
  int frames = 10;
  bool quick = false;
  app.add_option("--scene-root", scene_root, "folder of the shared scenes");
  app.add_option("--frames", frames, "animated frames per scene (median reported)")
      ->check(CLI::Range(1, 1000));
  app.add_option("--instances", counts,
                 "comma-separated instance counts of the moving-instances scene");
  app.add_option("--res", res, "primary ray resolution WxH");
  app.add_option("--json", json_path, "JSON output file");
  app.add_flag("--quick", quick, "tiny sizes, one frame (smoke test)");
  CLI11_PARSE(app, argc, argv);
  int width = 640, height = 360;
  if (std::sscanf(res.c_str(), "%dx%d", &width, &height) != 2 || width <= 0 || height <= 0) {
    std::fprintf(stderr, "kestrel_scene_bench: bad --res '%s'\n", res.c_str());
    return 2;
  }
  if (quick) {
    frames = 2;
    counts = "1000";
    width = 64, height = 36;
  }
  ThreadLimit one_thread(1);
  Json json;
  try {
    // 1. Bunny grid: 16 instances vs flattened.
    const std::string bunny = scene_root + "/stanford_bunny/stanford_bunny.obj";
    const std::string grid = scene_root + "/bunny_grid/bunny_grid.obj";
    const std::string inst_file = scene_root + "/bunny_grid/bunny_grid.instances.txt";
    if (!quick && std::filesystem::exists(bunny) && std::filesystem::exists(grid) &&
        std::filesystem::exists(inst_file)) {
      const Scene flat_scene = load_scene(grid);
      InstancedScene two;
      const MeshId b = two.add_mesh(merge(load_scene(bunny)));
      for (const Affine3& t : load_instance_transforms(inst_file)) two.add_instance(b, t);
      // The grid's ground quad (its last two triangles) as one more instance.
      const TriangleMesh all = merge(flat_scene);
      TriangleMesh ground;
      for (size_t k = all.indices.size() - 6; k < all.indices.size(); ++k) {
        ground.indices.push_back(uint32_t(ground.positions.size()));
        ground.positions.push_back(all.positions[all.indices[k]]);
      }
      two.add_instance(two.add_mesh(ground), Affine3{});
      const CommitStats cs = two.commit();
      const Accel flat = build_accel(flat_scene, BuildConfig{});
      const auto cam = tools::named_view(flat_scene, "framing");
      const std::vector<Ray> primary = tools::primary_rays(*cam, width, height);
      const Vec3 light = tools::default_light(tools::scene_bounds(flat_scene));
      const std::vector<Ray> diffuse =
          tools::secondary_rays(flat, flat_scene, primary, tools::RayKind::diffuse, light, 3);
      fmt::print(
          "bunny grid: 16 bunny instances + ground; BLAS build {:.1f} ms, TLAS {:.3f} ms; {:.1f} "
          "MB two-level vs {:.1f} MB flat\n",
          cs.blas_build_ms, cs.tlas_ms, two.memory_bytes() / 1e6, flat.memory_bytes() / 1e6);
      for (auto [kind, rays] : {std::pair{"primary", &primary}, std::pair{"diffuse", &diffuse}}) {
        std::vector<InstanceHit> ih(rays->size());
        std::vector<Hit> fh(rays->size());
        std::vector<double> a_ms, b_ms;
        for (int r = 0; r < std::max(5, frames); ++r) {
          Timer ta;
          two.trace(*rays, ih);
          a_ms.push_back(ta.ms());
          Timer tb;
          trace(flat, *rays, fh, TraceOptions{std::nullopt, false, std::nullopt});
          b_ms.push_back(tb.ms());
        }
        size_t same = 0;
        for (size_t i = 0; i < rays->size(); ++i) same += ih[i].hit() == fh[i].hit();
        const double two_mr = rays->size() / (median(a_ms) * 1e3),
                     flat_mr = rays->size() / (median(b_ms) * 1e3);
        fmt::print(
            "  {:<8} {:8} rays: two-level {:6.2f} Mrays/s, flattened {:6.2f} Mrays/s, two-level "
            "cost {:.2f}x flat; "
            "hit/miss agree {:.3f}%\n",
            kind, rays->size(), two_mr, flat_mr, flat_mr / two_mr,
            100.0 * double(same) / double(rays->size()));
        json.add(
            fmt::format("{{\"scene\": \"bunny_grid\", \"rays\": \"{}\", \"two_level_mrays\": "
                        "{:.3f}, \"flat_mrays\": {:.3f}, "
                        "\"penalty\": {:.3f}}}",
                        kind, two_mr, flat_mr, flat_mr / two_mr));
        if (rays != &primary) continue;
        // The camera rays with packets forced on, both ways, and as single rays through the
        // TLAS, alternating (the two-level default above chooses by timing).
        std::vector<double> tp_ms, fp_ms, ts_ms;
        TraceOptions packets, single;
        packets.packets = true, single.packets = false;
        for (int r = 0; r < std::max(5, frames); ++r) {
          Timer ta;
          two.trace(*rays, ih, 0xFFFFFFFFu, packets);
          tp_ms.push_back(ta.ms());
          Timer tb;
          trace(flat, *rays, fh, packets);
          fp_ms.push_back(tb.ms());
          Timer tc;
          two.trace(*rays, ih, 0xFFFFFFFFu, single);
          ts_ms.push_back(tc.ms());
        }
        fmt::print(
            "  primary as packets: two-level {:6.2f} Mrays/s, flattened {:6.2f}; two-level as "
            "single rays {:6.2f}\n",
            rays->size() / (median(tp_ms) * 1e3), rays->size() / (median(fp_ms) * 1e3),
            rays->size() / (median(ts_ms) * 1e3));
      }
      // The diffuse rays shuffled (a renderer's bounces after compaction), through the TLAS:
      // stream mode on against off, alternating.
      std::vector<Ray> shuffled = diffuse;
      std::shuffle(shuffled.begin(), shuffled.end(), std::mt19937(11));
      std::vector<InstanceHit> sh(shuffled.size()), nh(shuffled.size());
      std::vector<double> on_ms, off_ms;
      TraceOptions on, off;
      on.stream = true;
      off.stream = false;
      for (int r = 0; r < std::max(5, frames); ++r) {
        Timer ta;
        two.trace(shuffled, sh, 0xFFFFFFFFu, on);
        on_ms.push_back(ta.ms());
        Timer tb;
        two.trace(shuffled, nh, 0xFFFFFFFFu, off);
        off_ms.push_back(tb.ms());
      }
      size_t same = 0;
      for (size_t i = 0; i < sh.size(); ++i)
        same += sh[i].prim_id == nh[i].prim_id && sh[i].instance_id == nh[i].instance_id;
      const double on_mr = sh.size() / (median(on_ms) * 1e3),
                   off_mr = sh.size() / (median(off_ms) * 1e3);
      fmt::print(
          "  shuffled {:8} diffuse rays, two-level: stream {:6.2f} Mrays/s, no stream {:6.2f}: "
          "{:.2f}x; same hits {:.3f}%\n",
          sh.size(), on_mr, off_mr, on_mr / off_mr, 100.0 * double(same) / double(sh.size()));
      json.add(
          fmt::format("{{\"scene\": \"bunny_grid\", \"rays\": \"diffuse_shuffled\", "
                      "\"stream_mrays\": {:.3f}, \"no_stream_mrays\": {:.3f}}}",
                      on_mr, off_mr));
    }

    // 2. Moving instances.
    std::stringstream ss(counts);
    for (std::string c; std::getline(ss, c, ',');) {
      const size_t n = std::stoull(c);
      InstancedScene scene;
      const MeshId meshes[3] = {scene.add_mesh(sphere_mesh(12, 24, 0.4f)),
                                scene.add_mesh(box_mesh(0.35f)),
                                scene.add_mesh(sphere_mesh(4, 6, 0.45f))};
      const int side = int(std::ceil(std::sqrt(double(n))));
      std::vector<InstanceId> ids;
      auto place = [&](size_t i, float time) {
        const float x = float(i % size_t(side)), z = float(i / size_t(side));
        const float y = 0.5f * std::sin(0.7f * x + 0.3f * z + 2.0f * time);
        return Affine3::translation({x, y, z}) * Affine3::rotation_y(40.0f * time + float(i % 97));
      };
      for (size_t i = 0; i < n; ++i) ids.push_back(scene.add_instance(meshes[i % 3], place(i, 0)));
      scene.commit();
      const float half = 0.5f * float(side);
      tools::PinholeCamera cam{
          {half, 0.6f * float(side) + 3, -0.3f * float(side) - 3}, {half, 0, half}, 50.0f};
      const std::vector<Ray> rays = tools::primary_rays(cam, width, height);
      std::vector<InstanceHit> hits(rays.size());
      std::vector<double> update_ms, tlas_ms, trace_ms;
      for (int f = 1; f <= frames; ++f) {
        Timer tu;
        for (size_t i = 0; i < n; ++i) scene.set_transform(ids[i], place(i, 0.1f * float(f)));
        update_ms.push_back(tu.ms());
        tlas_ms.push_back(scene.commit().tlas_ms);
        Timer tt;
        scene.trace(rays, hits);
        trace_ms.push_back(tt.ms());
      }
      size_t hit = 0;
      for (const InstanceHit& h : hits) hit += h.hit();
      const double mr = rays.size() / (median(trace_ms) * 1e3);
      fmt::print(
          "moving instances: {:8} instances of 3 meshes: set_transform {:8.2f} ms, TLAS rebuild "
          "{:8.2f} ms "
          "({:.2f} M instances/s), trace {:6.2f} Mrays/s ({:.0f}% hit)\n",
          n, median(update_ms), median(tlas_ms), n / (median(tlas_ms) * 1e3), mr,
          100.0 * hit / rays.size());
      json.add(
          fmt::format("{{\"scene\": \"moving_instances\", \"instances\": {}, \"set_transform_ms\": "
                      "{:.3f}, \"tlas_ms\": {:.3f}, "
                      "\"trace_mrays\": {:.3f}}}",
                      n, median(update_ms), median(tlas_ms), mr));
    }

    // 3. Animated glTF scenes: node animations and morph targets, per frame.
    for (const char* rel :
         {"gltf_truck_fleet/truck_fleet.gltf", "gltf_cesium_milk_truck/CesiumMilkTruck.gltf",
          "gltf_box_animated/BoxAnimated.gltf", "gltf_animated_morph_cube/AnimatedMorphCube.gltf",
          "gltf_morph_stress_test/MorphStressTest.gltf"}) {
      const std::string path = scene_root + "/" + rel;
      if (!std::filesystem::exists(path)) continue;
      GltfInstances anim = GltfInstances::load(path);
      InstancedScene scene;
      anim.add_to(scene);
      scene.commit();
      const Scene flat = scene.flatten();
      const auto cam = tools::named_view(flat, "framing");
      const std::vector<Ray> rays = tools::primary_rays(*cam, width, height);
      std::vector<InstanceHit> hits(rays.size());
      std::vector<double> tlas_ms, refit_ms, build_ms, trace_ms, pose_ms;
      size_t refits = 0, builds = 0;
      const double dt = anim.duration() > 0 ? anim.duration() / double(frames) : 0.1;
      for (int f = 1; f <= frames; ++f) {
        Timer tp;
        anim.set_time(scene, dt * f);
        pose_ms.push_back(tp.ms());
        const CommitStats st = scene.commit();
        tlas_ms.push_back(st.tlas_ms);
        if (st.blas_refits) refit_ms.push_back(st.blas_refit_ms);
        if (st.blas_builds) build_ms.push_back(st.blas_build_ms);
        refits += st.blas_refits;
        builds += st.blas_builds;
        Timer tt;
        scene.trace(rays, hits);
        trace_ms.push_back(tt.ms());
      }
      const double mr = rays.size() / (median(trace_ms) * 1e3);
      // The same rays with the kernel fixed, alternating: lane packets through the TLAS or
      // single rays (the default above chooses by timing).
      std::vector<double> packet_ms, single_ms;
      for (int r = 0; r < std::max(3, frames); ++r)
        for (bool packets : {true, false}) {
          TraceOptions opt;
          opt.packets = packets;
          Timer t;
          scene.trace(rays, hits, 0xFFFFFFFFu, opt);
          (packets ? packet_ms : single_ms).push_back(t.ms());
        }
      const double mr_packets = rays.size() / (median(packet_ms) * 1e3),
                   mr_single = rays.size() / (median(single_ms) * 1e3);
      const std::string name = std::filesystem::path(path).stem().string();
      fmt::print(
          "animated {:<18} {:3} meshes {:4} instances: pose {:6.3f} ms, TLAS {:6.3f} ms, BLAS "
          "refits {:3} ({:6.3f} ms), "
          "rebuilds {:3} ({:6.2f} ms), trace {:6.2f} Mrays/s (packets {:6.2f}, single rays "
          "{:6.2f})\n",
          name, anim.mesh_count(), anim.instance_count(), median(pose_ms), median(tlas_ms), refits,
          median(refit_ms), builds, median(build_ms), mr, mr_packets, mr_single);
      json.add(fmt::format(
          "{{\"scene\": \"{}\", \"instances\": {}, \"tlas_ms\": {:.4f}, \"refit_ms\": {:.4f}, "
          "\"refits\": {}, "
          "\"rebuilds\": {}, \"trace_mrays\": {:.3f}, \"packets_mrays\": {:.3f}, "
          "\"single_mrays\": {:.3f}}}",
          name, anim.instance_count(), median(tlas_ms), median(refit_ms), refits, builds, mr,
          mr_packets, mr_single));
    }

    // 4. Deforming mesh: refit per frame.
    const std::string lambo = scene_root + "/lamborghini/lamborghini.obj";
    if (!quick && std::filesystem::exists(lambo)) {
      const TriangleMesh mesh = merge(load_scene(lambo));
      InstancedScene scene;
      const MeshId m = scene.add_mesh(mesh);
      scene.add_instance(m, Affine3{});
      const CommitStats first = scene.commit();
      Bounds3 b;
      for (const Vec3& p : mesh.positions) {
        b.lo = {std::min(b.lo.x, p.x), std::min(b.lo.y, p.y), std::min(b.lo.z, p.z)};
        b.hi = {std::max(b.hi.x, p.x), std::max(b.hi.y, p.y), std::max(b.hi.z, p.z)};
      }
      const float amp = 0.01f * (b.hi.y - b.lo.y), k = 6.0f / std::max(1e-6f, b.hi.x - b.lo.x);
      std::vector<Vec3> moved(mesh.positions.size());
      std::vector<double> refit_ms, build_ms, embree_ms;
      size_t refits = 0, builds = 0;
#ifdef KESTREL_HAVE_EMBREE
      Scene one_mesh;
      one_mesh.meshes.push_back(mesh);
      peer::EmbreeScene embree(one_mesh, peer::EmbreeQuality::refit, 1);
#endif
      for (int f = 1; f <= frames; ++f) {
        for (size_t i = 0; i < moved.size(); ++i) {
          const Vec3 p = mesh.positions[i];
          moved[i] = {p.x, p.y + amp * std::sin(k * p.x + 0.5f * float(f)), p.z};
        }
        scene.update_vertices(m, moved);
        const CommitStats s = scene.commit();
        if (s.blas_refits) refit_ms.push_back(s.blas_refit_ms);
        if (s.blas_builds) build_ms.push_back(s.blas_build_ms);
        refits += s.blas_refits;
        builds += s.blas_builds;
#ifdef KESTREL_HAVE_EMBREE
        embree_ms.push_back(embree.update_vertices(moved));  // the same frame, alternating
#endif
      }
      const double embree_refit = embree_ms.empty() ? 0.0 : median(embree_ms);
      fmt::print(
          "deforming Lamborghini ({} triangles): first build {:.1f} ms; per frame: {} refits "
          "(median {:.2f} ms), "
          "{} rebuilds (median {:.1f} ms)",
          mesh.triangle_count(), first.blas_build_ms, refits, median(refit_ms), builds,
          median(build_ms));
      if (!embree_ms.empty())
        fmt::print("; Embree REFIT commit {:.2f} ms: kestrel {:.2f}x Embree's speed", embree_refit,
                   embree_refit / median(refit_ms));
      fmt::print("\n");
      json.add(
          fmt::format("{{\"scene\": \"deforming_lamborghini\", \"triangles\": {}, \"refit_ms\": "
                      "{:.3f}, \"refits\": {}, "
                      "\"rebuilds\": {}, \"embree_refit_ms\": {:.3f}}}",
                      mesh.triangle_count(), median(refit_ms), refits, builds, embree_refit));
    }
  } catch (const std::exception& e) {
    std::fprintf(stderr, "kestrel_scene_bench: %s\n", e.what());
    return 1;
  }
  std::ofstream(json_path) << "{\n  \"results\": [\n" << json.body << "\n  ]\n}\n";
  return 0;
}
