// Two-level scenes against their flattened copies (one BVH over world-space triangles), ray
// by ray; refit against rebuild; transform updates; masks; every bad input.
#include <gtest/gtest.h>

#include <fmt/format.h>

#include <algorithm>
#include <cmath>

#include "core/vec.h"
#include "kestrel/error.h"
#include "kestrel/kestrel.h"
#include "support/oracles.h"

#include "scene/flattened_oracle.h"

namespace kestrel {
namespace {

using namespace test_two_level;

TEST(Instances, SameHitsAsTheFlattenedScene) {
  Fixture f = make_fixture();
  const CommitStats s = f.scene.commit();
  EXPECT_EQ(s.blas_builds, 2u);
  EXPECT_EQ(s.instances, 6u);
  expect_matches_flattened(f.scene, f.ids, "initial");
}

// Stream mode through the TLAS: rays reordered, hits identical and in the caller's order.
TEST(Instances, StreamModeGivesTheSameHitsInTheCallersOrder) {
  Fixture f = make_fixture();
  f.scene.commit();
  const std::vector<Ray> rays = rays_through(f.scene.flatten(), 20000, 23);
  TraceOptions off, on;
  off.stream = false;
  on.stream = true;
  std::vector<InstanceHit> want(rays.size());
  std::vector<uint8_t> want_occ(rays.size());
  f.scene.trace(rays, want, 0xFFFFFFFFu, off);
  f.scene.occluded(rays, want_occ, 0xFFFFFFFFu, off);
  size_t hits = 0;
  for (const InstanceHit& h : want) hits += h.hit();
  EXPECT_GT(hits, rays.size() / 10);
  for (int threads : {1, 2}) {
    ThreadLimit limit(threads);
    std::vector<InstanceHit> got(rays.size());
    std::vector<uint8_t> occ(rays.size());
    f.scene.trace(rays, got, 0xFFFFFFFFu, on);
    f.scene.occluded(rays, occ, 0xFFFFFFFFu, on);
    for (size_t i = 0; i < rays.size(); ++i) {
      ASSERT_EQ(got[i].instance_id, want[i].instance_id) << "ray " << i;
      ASSERT_EQ(got[i].prim_id, want[i].prim_id) << "ray " << i;
      ASSERT_EQ(got[i].t, want[i].t) << "ray " << i;
      ASSERT_EQ(got[i].u, want[i].u) << "ray " << i;
      ASSERT_EQ(occ[i], want_occ[i]) << "ray " << i;
    }
  }
}

// Coherent rays as lane packets through the TLAS and into each BLAS: the single rays' hits,
// bit for bit, for camera rays (packets that straddle the image's centre lines split) and
// shadow rays towards one point, through rotated, scaled, mirrored and duplicated instances
// (a duplicate ties at every t: the smaller instance id must win).
TEST(Instances, PacketsGiveTheSingleRaysHits) {
  Fixture f = make_fixture();
  const MeshId a = f.scene.add_mesh(f.meshes[0]);
  const Affine3 mirrored = Affine3::translation({0.8f, 0.9f, 1.2f}) * Affine3::rotation_y(-20.0f) *
                           Affine3::scaling({-1.1f, 0.9f, 1.3f});
  f.ids.push_back(f.scene.add_instance(a, mirrored));
  f.ids.push_back(f.scene.add_instance(a, mirrored));  // the same triangles again
  Affine3 oblique;  // every entry non-zero: the object-space rays' rounding shows
  oblique.m[0] = 0.9f, oblique.m[1] = 0.31f, oblique.m[2] = -0.22f, oblique.m[3] = 2.1f;
  oblique.m[4] = -0.27f, oblique.m[5] = 0.93f, oblique.m[6] = 0.17f, oblique.m[7] = 0.6f;
  oblique.m[8] = 0.23f, oblique.m[9] = -0.13f, oblique.m[10] = 1.07f, oblique.m[11] = 1.9f;
  f.ids.push_back(f.scene.add_instance(a, oblique));
  f.scene.commit();
  const Bounds3 b = bounds_of(f.scene.flatten());
  const Vec3 c = (b.lo + b.hi) * 0.5f, e = b.hi - b.lo;
  std::vector<Ray> rays;
  const int w = 96, h = 64;
  for (const Vec3 eye :
       {c + Vec3{0.3f, 0.4f, 1.6f} * length(e), c - Vec3{1.2f, -0.5f, 0.7f} * length(e)}) {
    const Vec3 fwd = normalize(c - eye), right = normalize(cross(fwd, Vec3{0, 1, 0})),
               up = cross(right, fwd);
    for (int y = 0; y < h; ++y)
      for (int x = 0; x < w; ++x) {
        const float sx = (2.0f * (float(x) + 0.5f) / float(w) - 1.0f) * 0.3f,
                    sy = (1.0f - 2.0f * (float(y) + 0.5f) / float(h)) * 0.2f;
        rays.push_back({eye, fwd + right * sx + up * sy});
      }
  }
  const size_t camera = rays.size();
  std::vector<InstanceHit> first(camera);
  f.scene.trace(std::span<const Ray>(rays.data(), camera), first);
  const Vec3 light = b.hi + e * 0.5f;
  for (size_t i = 0; i < camera; ++i)
    if (first[i].hit()) {
      const Vec3 p = rays[i].org + rays[i].dir * (first[i].t * 0.999f);
      rays.push_back({p, light - p, 0.0f, 1.0f});
    }
  ASSERT_GT(rays.size() - camera, camera / 5);
  TraceOptions single, packets;
  single.packets = false;
  packets.packets = true;
  for (Isa isa : test::supported_isas()) {
    single.isa = packets.isa = isa;
    std::vector<InstanceHit> want(rays.size()), got(rays.size());
    std::vector<uint8_t> want_occ(rays.size()), occ(rays.size());
    f.scene.trace(rays, want, 0xFFFFFFFFu, single);
    f.scene.trace(rays, got, 0xFFFFFFFFu, packets);
    f.scene.occluded(rays, want_occ, 0xFFFFFFFFu, single);
    f.scene.occluded(rays, occ, 0xFFFFFFFFu, packets);
    // Unsaid: coherent runs go whichever way has been faster so far (both are timed).
    std::vector<InstanceHit> chosen(rays.size());
    std::vector<uint8_t> chosen_occ(rays.size());
    TraceOptions unsaid;
    unsaid.isa = isa;
    for (int round = 0; round < 3; ++round) {
      f.scene.trace(rays, chosen, 0xFFFFFFFFu, unsaid);
      f.scene.occluded(rays, chosen_occ, 0xFFFFFFFFu, unsaid);
      for (size_t i = 0; i < rays.size(); ++i) {
        ASSERT_EQ(chosen[i].instance_id, want[i].instance_id) << isa_name(isa) << " ray " << i;
        ASSERT_EQ(chosen[i].prim_id, want[i].prim_id) << isa_name(isa) << " ray " << i;
        ASSERT_EQ(chosen[i].t, want[i].t) << isa_name(isa) << " ray " << i;
        ASSERT_EQ(chosen_occ[i], want_occ[i]) << isa_name(isa) << " ray " << i;
      }
    }
    size_t hits = 0, duplicates = 0, blocked = 0;
    for (size_t i = 0; i < rays.size(); ++i) {
      hits += want[i].hit(), blocked += i >= camera && want_occ[i];
      duplicates += want[i].instance_id == f.ids[6];
      ASSERT_EQ(got[i].instance_id, want[i].instance_id) << isa_name(isa) << " ray " << i;
      ASSERT_EQ(got[i].prim_id, want[i].prim_id) << isa_name(isa) << " ray " << i;
      ASSERT_EQ(got[i].t, want[i].t) << isa_name(isa) << " ray " << i;
      ASSERT_EQ(got[i].u, want[i].u) << isa_name(isa) << " ray " << i;
      ASSERT_EQ(got[i].v, want[i].v) << isa_name(isa) << " ray " << i;
      ASSERT_EQ(occ[i], want_occ[i]) << isa_name(isa) << " ray " << i;
    }
    EXPECT_GT(hits, camera / 5) << isa_name(isa);
    EXPECT_GT(duplicates, 20u) << isa_name(isa);  // the tie is exercised
    EXPECT_GT(blocked, (rays.size() - camera) / 20) << isa_name(isa);
    EXPECT_LT(blocked, rays.size() - camera) << isa_name(isa);
    // Untraceable rays among them (the kernels take batches unscanned): misses, every other
    // ray's hit unchanged, both ways. The results start as hits, so every slot must be written.
    std::vector<Ray> bad = rays;
    const float nan = std::nanf(""), inf = INFINITY;
    for (size_t i = 3; i < bad.size(); i += 7) {
      switch (i % 4) {
        case 0:
          bad[i].org.x = inf;
          break;
        case 1:
          bad[i].dir.y = nan;
          break;
        case 2:
          bad[i].tmin = 2.0f, bad[i].tmax = 1.0f;
          break;
        default:
          bad[i].dir = {0, 0, 0};
          break;
      }
    }
    for (const TraceOptions& o : {single, packets, unsaid}) {
      std::vector<InstanceHit> b(bad.size(), InstanceHit{1.0f, 7, 3, 0.0f, 0.0f});
      std::vector<uint8_t> bo(bad.size(), 1);
      f.scene.trace(bad, b, 0xFFFFFFFFu, o);
      f.scene.occluded(bad, bo, 0xFFFFFFFFu, o);
      for (size_t i = 0; i < bad.size(); ++i) {
        const bool untraceable = i >= 3 && (i - 3) % 7 == 0;
        ASSERT_EQ(b[i].instance_id, untraceable ? invalid_id : want[i].instance_id)
            << isa_name(isa) << " ray " << i;
        ASSERT_EQ(b[i].prim_id, untraceable ? invalid_id : want[i].prim_id) << " ray " << i;
        ASSERT_EQ(bo[i], untraceable ? 0 : want_occ[i]) << isa_name(isa) << " ray " << i;
      }
    }
  }
}

TEST(Instances, UpdatingATransformMovesTheHits) {
  Fixture f = make_fixture();
  f.scene.commit();
  // A ray straight at instance 1 (a sphere) hits it; move the instance away: it misses
  // there and hits at the new place, and the flattened comparison still holds.
  Scene one;
  one.meshes.push_back(f.scene.flatten().meshes[1]);
  const Bounds3 b1 = bounds_of(one);
  const Vec3 c = (b1.lo + b1.hi) * 0.5f;
  const Ray ray{{c.x, c.y, c.z - 50}, {0, 0, 1}};
  std::vector<InstanceHit> h(1);
  f.scene.trace(std::span(&ray, 1), h);
  ASSERT_TRUE(h[0].hit());
  EXPECT_EQ(h[0].instance_id, f.ids[1]);
  f.scene.set_transform(f.ids[1], Affine3::translation({100, 0, 0}));
  const CommitStats s = f.scene.commit();
  EXPECT_EQ(s.blas_builds + s.blas_refits, 0u);  // only the TLAS changed
  f.scene.trace(std::span(&ray, 1), h);
  EXPECT_TRUE(!h[0].hit() || h[0].instance_id != f.ids[1]);
  const Ray there{{100, 0, -50}, {0, 0, 1}};
  f.scene.trace(std::span(&there, 1), h);
  ASSERT_TRUE(h[0].hit());
  EXPECT_EQ(h[0].instance_id, f.ids[1]);
  EXPECT_NEAR(h[0].t, 50.0f - 0.5f, 0.02f);  // the tessellated sphere of radius 0.5, moved
  expect_matches_flattened(f.scene, f.ids, "moved");
}

TEST(Instances, RefitGivesTheSameHitsAsRebuild) {
  Fixture f = make_fixture();
  f.scene.commit();
  std::vector<Vec3> moved = f.meshes[0].positions;
  for (Vec3& p : moved) p = {p.x + 0.05f * std::sin(6 * p.y), p.y, p.z + 0.05f * std::cos(5 * p.x)};
  f.scene.update_vertices(0, moved);
  const CommitStats s = f.scene.commit();
  EXPECT_EQ(s.blas_refits + s.blas_builds, 1u);
  EXPECT_EQ(s.blas_refits, 1u) << "a small deformation should refit";
  // The reference is a fresh BVH over the moved, flattened triangles.
  expect_matches_flattened(f.scene, f.ids, "refit");
  // A large deformation crosses the SAH threshold and rebuilds.
  test::Rng rng{5};
  for (Vec3& p : moved) p = rng.in_box({-3, -3, -3}, {3, 3, 3});
  f.scene.update_vertices(0, moved);
  const CommitStats s2 = f.scene.commit();
  EXPECT_EQ(s2.blas_builds, 1u);
  expect_matches_flattened(f.scene, f.ids, "rebuilt");
}

TEST(Instances, MasksHideInstances) {
  Fixture f = make_fixture();
  for (InstanceId id : f.ids) f.scene.set_mask(id, 0x2);
  f.scene.commit();
  const std::vector<Ray> rays = rays_through(f.scene.flatten(), 500, 3);
  std::vector<InstanceHit> h(rays.size());
  f.scene.trace(rays, h, 0x1);
  for (const InstanceHit& x : h) EXPECT_FALSE(x.hit());
  f.scene.trace(rays, h, 0x3);
  size_t n = 0;
  for (const InstanceHit& x : h) n += x.hit();
  EXPECT_GT(n, 50u);
}

// any_hits names a triangle the ray really hits in (tmin, tmax) (a double-precision test on
// the flattened scene) exactly where occluded() says it is blocked; through the TLAS and
// through one identity instance's own BLAS.
TEST(Instances, AnyHitsNameATriangleTheRayHits) {
  auto hits_at = [](const Vec3& o, const Vec3& d, const Vec3& a, const Vec3& b, const Vec3& c) {
    const double e1[3] = {double(b.x) - a.x, double(b.y) - a.y, double(b.z) - a.z},
                 e2[3] = {double(c.x) - a.x, double(c.y) - a.y, double(c.z) - a.z},
                 s[3] = {double(o.x) - a.x, double(o.y) - a.y, double(o.z) - a.z},
                 dd[3] = {d.x, d.y, d.z};
    auto cross = [](const double* x, const double* y, double* r) {
      r[0] = x[1] * y[2] - x[2] * y[1], r[1] = x[2] * y[0] - x[0] * y[2],
      r[2] = x[0] * y[1] - x[1] * y[0];
    };
    auto dot = [](const double* x, const double* y) {
      return x[0] * y[0] + x[1] * y[1] + x[2] * y[2];
    };
    double p[3], q[3];
    cross(dd, e2, p);
    const double det = dot(e1, p);
    cross(s, e1, q);
    const double u = dot(s, p) / det, v = dot(dd, q) / det;
    const double slack = 1e-6;  // edges: float kernels against doubles
    return std::pair{u >= -slack && v >= -slack && u + v <= 1 + slack, dot(e2, q) / det};
  };
  for (const bool direct : {false, true}) {
    Fixture f = make_fixture();
    if (direct) {  // one identity instance: the BLAS alone
      f = Fixture{};
      f.meshes.push_back(test::random_soup(800, 0.2f, 3).meshes[0]);
      f.ids.push_back(f.scene.add_instance(f.scene.add_mesh(f.meshes[0]), Affine3{}));
    }
    f.scene.commit();
    const Scene flat = f.scene.flatten();
    std::vector<Ray> rays = rays_through(flat, 4000, 29);
    for (size_t i = 0; i < rays.size(); i += 2) rays[i].tmax = 0.5f;  // some fall short
    std::vector<InstanceHit> any(rays.size());
    std::vector<uint8_t> occ(rays.size());
    f.scene.any_hits(rays, any);
    f.scene.occluded(rays, occ);
    size_t blocked = 0;
    for (size_t i = 0; i < rays.size(); ++i) {
      ASSERT_EQ(any[i].hit(), occ[i] != 0) << "ray " << i << (direct ? " direct" : "");
      if (!any[i].hit()) continue;
      ++blocked;
      const size_t k =
          size_t(std::find(f.ids.begin(), f.ids.end(), any[i].instance_id) - f.ids.begin());
      ASSERT_LT(k, flat.meshes.size());
      const TriangleMesh& m = flat.meshes[k];
      ASSERT_LT(any[i].prim_id, m.triangle_count());
      const uint32_t* t = &m.indices[3 * size_t(any[i].prim_id)];
      const auto [inside, t_hit] = hits_at(rays[i].org, rays[i].dir, m.positions[t[0]],
                                           m.positions[t[1]], m.positions[t[2]]);
      EXPECT_TRUE(inside) << "ray " << i;
      EXPECT_NEAR(t_hit, any[i].t, 1e-4 * std::max(1.0, t_hit)) << "ray " << i;
      EXPECT_LE(any[i].t, rays[i].tmax);
    }
    EXPECT_GT(blocked, rays.size() / 10);
    EXPECT_LT(blocked, rays.size());
  }
}

TEST(Instances, RemovedInstancesAndMeshes) {
  Fixture f = make_fixture();
  f.scene.remove_instance(f.ids[0]);
  f.scene.remove_instance(f.ids[2]);
  f.scene.remove_instance(f.ids[4]);
  f.scene.commit();
  EXPECT_EQ(f.scene.instance_count(), 3u);
  f.scene.remove_mesh(0);  // no instance uses the soup any more
  EXPECT_EQ(f.scene.mesh_count(), 1u);
  f.scene.commit();
  const std::vector<Ray> rays = rays_through(f.scene.flatten(), 500, 4);
  std::vector<InstanceHit> h(rays.size());
  f.scene.trace(rays, h);
  for (const InstanceHit& x : h)
    if (x.hit()) {
      EXPECT_TRUE(x.instance_id == f.ids[1] || x.instance_id == f.ids[3] ||
                  x.instance_id == f.ids[5]);
    }
}

TEST(Instances, BadInputIsAClearError) {
  InstancedScene s;
  const MeshId m = s.add_mesh(test::closed_sphere(1, {0, 0, 0}, 1).meshes[0]);
  Affine3 nan;
  nan.m[5] = std::nanf("");
  auto message = [](auto&& fn) {
    try {
      fn();
    } catch (const Error& e) {
      return std::string(e.what());
    }
    return std::string("no error");
  };
  EXPECT_NE(message([&] { s.add_instance(m, nan); }).find("m[5] is nan"), std::string::npos);
  EXPECT_NE(message([&] {
              s.add_instance(m, Affine3::scaling({1, 0, 1}));
            }).find("singular"),
            std::string::npos);
  EXPECT_NE(message([&] { s.add_instance(7, Affine3{}); }).find("no mesh 7"), std::string::npos);
  const InstanceId i = s.add_instance(m, Affine3{});
  EXPECT_NE(message([&] {
              s.set_transform(i, Affine3::scaling({0, 0, 0}));
            }).find("instance 0: transform is singular"),
            std::string::npos);
  EXPECT_NE(message([&] { s.set_transform(9, Affine3{}); }).find("no instance 9"),
            std::string::npos);
  EXPECT_NE(
      message([&] { s.update_vertices(m, std::vector<Vec3>(3)); }).find("has 42 vertices, got 3"),
      std::string::npos);
  EXPECT_NE(message([&] { s.remove_mesh(m); }).find("used by instance 0"), std::string::npos);
  std::vector<Ray> rays(2);
  std::vector<InstanceHit> hits(1);
  s.commit();
  EXPECT_THROW(s.trace(rays, hits), Error);
  // Empty scene and NaN rays: misses.
  InstancedScene empty;
  empty.commit();
  std::vector<InstanceHit> h(2);
  empty.trace(rays, h);
  EXPECT_FALSE(h[0].hit());
  const Ray bad{{std::nanf(""), 0, 0}, {1, 0, 0}};
  std::vector<InstanceHit> h1(1);
  s.trace(std::span(&bad, 1), h1);
  EXPECT_FALSE(h1[0].hit());
}

TEST(Instances, AffineInverseRoundTrips) {
  const Affine3 a =
      Affine3::translation({1, -2, 3}) * Affine3::rotation_y(33) * Affine3::scaling({2, 0.5f, 3});
  const Affine3 i = inverse(a);
  test::Rng rng{1};
  for (int k = 0; k < 100; ++k) {
    const Vec3 p = rng.in_box({-5, -5, -5}, {5, 5, 5});
    const Vec3 q = i.point(a.point(p));
    EXPECT_NEAR(q.x, p.x, 1e-4f);
    EXPECT_NEAR(q.y, p.y, 1e-4f);
    EXPECT_NEAR(q.z, p.z, 1e-4f);
  }
}

TEST(Instances, BunnyGridInstancesFileLoadsAsSixteenInstancesOfOneMesh) {
  auto path = test::shared_scene("bunny_grid/bunny_grid.instances.txt");
  auto bunny = test::shared_scene("stanford_bunny/stanford_bunny.obj");
  if (!path || !bunny) GTEST_SKIP() << "shared scenes absent";
  const std::vector<Affine3> t = load_instance_transforms(*path);
  ASSERT_EQ(t.size(), 16u);
  InstancedScene s;
  const MeshId m = s.add_mesh(load_scene(*bunny).meshes[0]);
  for (const Affine3& a : t) s.add_instance(m, a);
  const CommitStats stats = s.commit();
  EXPECT_EQ(stats.blas_builds, 1u);
  EXPECT_EQ(stats.instances, 16u);
  // The flattened instances are the bunny grid's OBJ (without its ground quad), vertex for
  // vertex up to float rounding.
  const Scene grid = load_scene(*test::shared_scene("bunny_grid/bunny_grid.obj"));
  const Scene flat = s.flatten();
  size_t grid_tris = 0;
  for (const auto& mm : grid.meshes) grid_tris += mm.triangle_count();
  size_t flat_tris = 0;
  for (const auto& mm : flat.meshes) flat_tris += mm.triangle_count();
  ASSERT_EQ(flat_tris + 2, grid_tris);
  // Copy k of the grid is triangles [69451 k, 69451 (k + 1)): compare every vertex.
  const test::Soup g = test::flatten(grid), fl = test::flatten(flat);
  float worst = 0;
  for (size_t i = 0; i < fl.triangles.size(); ++i) {
    const Triangle& x = fl.triangles[i];
    const Triangle& y = g.triangles[i];
    for (const auto& [p, q] : {std::pair{x.v0, y.v0}, std::pair{x.v1, y.v1}, std::pair{x.v2, y.v2}})
      worst = std::max({worst, std::fabs(p.x - q.x), std::fabs(p.y - q.y), std::fabs(p.z - q.z)});
  }
  EXPECT_LT(worst, 1e-5f);
}

TEST(Instances, InstanceFileErrorsNameFileAndLine) {
  const std::string p =
      test::write_temp_file("bad.instances.txt", "# header\n1 1 1 0 0 0 0\n1 1 1 0 0\n");
  try {
    load_instance_transforms(p);
    FAIL();
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("bad.instances.txt:3"), std::string::npos) << e.what();
  }
  const std::string q = test::write_temp_file("sing.instances.txt", "0 1 1 0 0 0 0\n");
  EXPECT_THROW(load_instance_transforms(q), Error);
}

}  // namespace
}  // namespace kestrel

namespace kestrel {
namespace {

// Total triangles and bounds of a flattened scene.
std::pair<size_t, Bounds3> summary(const Scene& s) {
  size_t n = 0;
  for (const TriangleMesh& m : s.meshes) n += m.triangle_count();
  return {n, bounds_of(s)};
}

// A glTF file as instances at t = 0 is the flattening loader's scene: same triangle count and
// bounds; meshes referenced by several nodes are built once.
TEST(GltfInstances, MatchTheFlatteningLoaderAndShareMeshes) {
  struct Case {
    const char* rel;
    size_t meshes, instances;
  };
  for (const Case& c : {Case{"gltf_truck_fleet/truck_fleet.gltf", 2, 192},
                        Case{"gltf_cesium_milk_truck/CesiumMilkTruck.gltf", 2, 3},
                        Case{"gltf_box_animated/BoxAnimated.gltf", 2, 2},
                        Case{"gltf_flight_helmet/FlightHelmet.gltf", 6, 6}}) {
    auto path = test::shared_scene(c.rel);
    if (!path) GTEST_SKIP() << "shared scenes absent";
    GltfInstances g = GltfInstances::load(*path);
    EXPECT_EQ(g.mesh_count(), c.meshes) << c.rel;
    EXPECT_EQ(g.instance_count(), c.instances) << c.rel;
    InstancedScene scene;
    g.add_to(scene);
    const CommitStats st = scene.commit();
    EXPECT_EQ(st.blas_builds, c.meshes) << c.rel;
    const auto [n, box] = summary(scene.flatten());
    const auto [n_ref, box_ref] = summary(load_scene(*path));
    EXPECT_EQ(n, n_ref) << c.rel;
    const float tol = 1e-4f * length(box_ref.hi - box_ref.lo);
    EXPECT_NEAR(box.lo.x, box_ref.lo.x, tol) << c.rel;
    EXPECT_NEAR(box.hi.y, box_ref.hi.y, tol) << c.rel;
    EXPECT_NEAR(box.hi.z, box_ref.hi.z, tol) << c.rel;
  }
}

// Animation: transforms move (box, trucks) and morph targets deform (cube) over time, the
// per-frame commit refits what moved, and hits follow.
TEST(GltfInstances, AnimationsMoveInstancesAndMorphMeshes) {
  auto box_path = test::shared_scene("gltf_box_animated/BoxAnimated.gltf");
  auto cube_path = test::shared_scene("gltf_animated_morph_cube/AnimatedMorphCube.gltf");
  if (!box_path || !cube_path) GTEST_SKIP() << "shared scenes absent";
  GltfInstances box = GltfInstances::load(*box_path);
  EXPECT_NEAR(box.duration(), 3.708, 0.01);
  InstancedScene s;
  box.add_to(s);
  s.commit();
  const Bounds3 b0 = bounds_of(s.flatten());
  box.set_time(s, 1.5);
  const CommitStats st = s.commit();
  EXPECT_EQ(st.blas_builds + st.blas_refits, 0u);  // rigid motion: the TLAS only
  const Bounds3 b1 = bounds_of(s.flatten());
  EXPECT_GT(
      std::fabs(b1.hi.y - b0.hi.y) + std::fabs(b1.lo.x - b0.lo.x) + std::fabs(b1.hi.z - b0.hi.z),
      1e-3f);
  expect_matches_flattened(s, {0, 1}, "box at 1.5 s");

  GltfInstances cube = GltfInstances::load(*cube_path);
  InstancedScene c;
  cube.add_to(c);
  c.commit();
  const std::vector<Vec3> p0 = c.flatten().meshes[0].positions;
  cube.set_time(c, 1.0);
  const CommitStats cs = c.commit();
  EXPECT_EQ(cs.blas_refits + cs.blas_builds, 1u);  // the morphing mesh
  const std::vector<Vec3> p1 = c.flatten().meshes[0].positions;
  float moved = 0;
  for (size_t i = 0; i < p0.size(); ++i) moved = std::max(moved, length(p1[i] - p0[i]));
  EXPECT_GT(moved, 1e-3f);
  expect_matches_flattened(c, {0}, "morph cube at 1 s");
}

TEST(GltfInstances, CubicSplineSamplersFollowTheHermiteSpline) {
  // One translation channel, keys at t = 0 and 1 stored as (in-tangent, value, out-tangent):
  // v0 = 0 with out-tangent 4, v1 = 1 with in-tangent 0. glTF 2.0 Appendix C: at u = 0.5 the
  // x offset is h10 * 4 + h01 * 1 = 0.125 * 4 + 0.5 = 1 (a linear blend of the values: 0.5);
  // at u = 0.25 it is 0.140625 * 4 + 0.15625 = 0.71875.
  const std::string path = test::write_temp_file("cubic.gltf", R"({"asset": {"version": "2.0"},
    "buffers": [{"byteLength": 116, "uri": "data:application/octet-stream;base64,AAAAAAAAAAAAAAAAAACAPwAAAAAAAAAAAAAAAAAAgD8AAAAAAAAAAAAAgD8AAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAIBAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAIA/AAAAAAAAAAAAAAAAAAAAAAAAAAA="}],
    "bufferViews": [{"buffer": 0, "byteOffset": 0, "byteLength": 36}, {"buffer": 0, "byteOffset": 36, "byteLength": 8},
                    {"buffer": 0, "byteOffset": 44, "byteLength": 72}],
    "accessors": [{"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3"},
                  {"bufferView": 1, "componentType": 5126, "count": 2, "type": "SCALAR", "min": [0], "max": [1]},
                  {"bufferView": 2, "componentType": 5126, "count": 6, "type": "VEC3"}],
    "meshes": [{"primitives": [{"attributes": {"POSITION": 0}}]}],
    "nodes": [{"mesh": 0}], "scenes": [{"nodes": [0]}], "scene": 0,
    "animations": [{"channels": [{"sampler": 0, "target": {"node": 0, "path": "translation"}}],
                    "samplers": [{"input": 1, "output": 2, "interpolation": "CUBICSPLINE"}]}]})");
  GltfInstances g = GltfInstances::load(path);
  InstancedScene s;
  g.add_to(s);
  for (auto [t, x] : {std::pair{0.0, 0.0f}, {0.25, 0.71875f}, {0.5, 1.0f}, {0.999999, 1.0f}}) {
    g.set_time(s, t);
    s.commit();
    EXPECT_NEAR(s.flatten().meshes[0].positions[0].x, x, 1e-5f) << "t = " << t;
  }
}

TEST(GltfInstances, BadFilesAreClearErrors) {
  const std::string bad = test::write_temp_file("bad_anim.gltf", R"({"asset": {"version": "2.0"},
    "nodes": [{"mesh": 3}], "scenes": [{"nodes": [0]}], "scene": 0})");
  try {
    GltfInstances::load(bad);
    FAIL() << "expected an error";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("bad_anim.gltf"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("missing mesh 3"), std::string::npos) << e.what();
  }
  EXPECT_THROW(GltfInstances::load("/nonexistent/x.gltf"), Error);
}

}  // namespace
}  // namespace kestrel
