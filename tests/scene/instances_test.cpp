// Two-level scenes against their flattened copies (one BVH over world-space triangles), ray
// by ray; refit against rebuild; transform updates; masks; every bad input.
#include <gtest/gtest.h>

#include <fmt/format.h>

#include <cmath>

#include "core/vec.h"
#include "kestrel/error.h"
#include "kestrel/kestrel.h"
#include "support/oracles.h"

namespace kestrel {
namespace {

Bounds3 bounds_of(const Scene& s) {
  Bounds3 b;
  for (const TriangleMesh& m : s.meshes)
    for (const Vec3& p : m.positions) {
      b.lo = {std::min(b.lo.x, p.x), std::min(b.lo.y, p.y), std::min(b.lo.z, p.z)};
      b.hi = {std::max(b.hi.x, p.x), std::max(b.hi.y, p.y), std::max(b.hi.z, p.z)};
    }
  return b;
}

// Rays from around the scene towards random points of random triangles (and some towards
// random points of the box, which may miss).
std::vector<Ray> rays_through(const Scene& scene, size_t n, uint64_t seed) {
  test::Rng rng{seed};
  const Bounds3 b = bounds_of(scene);
  const test::Soup soup = test::flatten(scene);
  const Vec3 c = (b.lo + b.hi) * 0.5f, e = b.hi - b.lo;
  const float r = length(e);
  std::vector<Ray> rays;
  for (size_t i = 0; i < n; ++i) {
    const Vec3 o = c + rng.on_sphere() * r;
    Vec3 target = rng.in_box(b.lo, b.hi);
    if (i % 4 != 0 && !soup.triangles.empty()) {
      const Triangle& t = soup.triangles[size_t(rng.uniform() * float(soup.triangles.size())) %
                                         soup.triangles.size()];
      float u = rng.uniform(), v = rng.uniform();
      if (u + v > 1) u = 1 - u, v = 1 - v;
      target = t.v0 + (t.v1 - t.v0) * u + (t.v2 - t.v0) * v;
    }
    rays.push_back({o, target - o});
  }
  return rays;
}

struct Fixture {
  InstancedScene scene;
  std::vector<TriangleMesh> meshes;
  std::vector<InstanceId> ids;
};

// Two meshes (a soup and a closed sphere), six instances with rotations, scales and moves.
Fixture make_fixture() {
  Fixture f;
  f.meshes.push_back(test::random_soup(800, 0.2f, 3).meshes[0]);
  f.meshes.push_back(test::closed_sphere(2, {0, 0, 0}, 0.5f).meshes[0]);
  const MeshId a = f.scene.add_mesh(f.meshes[0]);
  const MeshId b = f.scene.add_mesh(f.meshes[1]);
  for (int i = 0; i < 6; ++i) {
    const Affine3 t =
        Affine3::translation({1.7f * float(i % 3), 0.3f * float(i), 1.5f * float(i / 3)}) *
        Affine3::rotation_y(37.0f * float(i)) *
        Affine3::scaling({1.0f + 0.2f * float(i), 1.0f, 0.8f + 0.1f * float(i)});
    f.ids.push_back(f.scene.add_instance(i % 2 ? b : a, t));
  }
  return f;
}

// A world-space hit of the flattened scene, as (instance, local prim): flatten() emits one
// mesh per instance in id order, so global prim ids map back by mesh offsets.
struct Located {
  uint32_t instance, prim;
};
Located locate(const Scene& flat, uint32_t gid) {
  uint32_t inst = 0;
  for (const TriangleMesh& m : flat.meshes) {
    if (gid < m.triangle_count()) return {inst, gid};
    gid -= uint32_t(m.triangle_count());
    ++inst;
  }
  return {invalid_id, invalid_id};
}

void expect_matches_flattened(const InstancedScene& scene, const std::vector<InstanceId>& ids,
                              const std::string& what) {
  const Scene flat = scene.flatten();
  BuildConfig c;
  c.layout = Layout::bvh2;
  const Accel ref = build_accel(flat, c);
  const test::Soup soup = test::flatten(flat);
  const std::vector<Ray> rays = rays_through(flat, 3000, 17);
  std::vector<Hit> want(rays.size());
  trace(ref, rays, want);
  std::vector<uint8_t> want_occ(rays.size());
  occluded(ref, rays, want_occ);
  size_t hits = 0, tie_or_edge = 0;
  for (Isa isa : test::supported_isas()) {
    std::vector<InstanceHit> got(rays.size());
    TraceOptions opt;
    opt.isa = isa;
    scene.trace(rays, got, 0xFFFFFFFFu, opt);
    std::vector<uint8_t> occ(rays.size());
    scene.occluded(rays, occ, 0xFFFFFFFFu, opt);
    for (size_t i = 0; i < rays.size(); ++i) {
      const float scale = std::max(1.0f, std::fabs(want[i].t));
      if (want[i].hit() != got[i].hit() || occ[i] != want_occ[i]) {
        // Object-space rays round differently from world-space triangles: only a ray that
        // grazes an edge may differ. Count them; they must be rare.
        ++tie_or_edge;
        continue;
      }
      if (!want[i].hit()) continue;
      ++hits;
      const Located l = locate(flat, want[i].prim_id);
      if (ids[l.instance] != got[i].instance_id || l.prim != got[i].prim_id) {
        // A different triangle: either equally near (two triangles meeting where the ray
        // passes) or the reference's triangle is hit within rounding of one of its edges,
        // which the object-space ray may miss (rare; counted below).
        // Overlapping coplanar triangles (or two meeting where the ray passes): distances
        // equal to rounding, and world and object space round differently, so either may win.
        if (std::fabs(got[i].t - want[i].t) <= 1e-6f * scale) continue;
        const float w = 1 - want[i].u - want[i].v;
        const bool near_edge = std::min({want[i].u, want[i].v, w}) < 1e-3f;
        if (!near_edge) {
          ASSERT_NEAR(got[i].t, want[i].t, 2e-4f * scale) << what << " ray " << i;
        }
        ++tie_or_edge;
        continue;
      }
      // Object-space rays and world-space vertices round differently: t agrees to ~1e-5.
      ASSERT_NEAR(got[i].t, want[i].t, 2e-4f * scale) << what << " ray " << i;
      // Barycentrics are ill-conditioned for grazing rays; compare them where the ray meets
      // the triangle at more than ~6 degrees.
      const Triangle& tri = soup.triangles[want[i].prim_id];
      const Vec3 n = normalize(cross(tri.v1 - tri.v0, tri.v2 - tri.v0));
      if (std::fabs(dot(n, normalize(rays[i].dir))) > 0.1f) {
        ASSERT_NEAR(got[i].u, want[i].u, 2e-3f) << what << " ray " << i;
      }
    }
  }
  EXPECT_GT(hits, rays.size() / 10) << what;
  EXPECT_LE(tie_or_edge, rays.size() / 200 + 2) << what;
}

TEST(Instances, SameHitsAsTheFlattenedScene) {
  Fixture f = make_fixture();
  const CommitStats s = f.scene.commit();
  EXPECT_EQ(s.blas_builds, 2u);
  EXPECT_EQ(s.instances, 6u);
  expect_matches_flattened(f.scene, f.ids, "initial");
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

namespace kestrel {
namespace {

// The one scene model: a file becomes an Asset, an OBJ one identity instance per mesh, and a
// scene of one identity instance is traced through its BLAS alone — the same hits, bit for
// bit, as the single-level Accel over the same triangles (the oracle: brute force agrees).
TEST(Asset, OneIdentityInstanceTracesExactlyAsItsAccel) {
  Scene s = test::random_soup(1500, 0.15f, 11);
  s.source = "test:soup";
  const Scene copy = s;
  const Asset asset = Asset::from_scene(std::move(s));
  ASSERT_EQ(asset.scene().instance_count(), 1u);
  EXPECT_EQ(asset.source(), "test:soup");
  EXPECT_EQ(asset.triangle_count(), copy.triangle_count());
  const Bounds3 want_bounds = scene_bounds(copy), got_bounds = asset.bounds();
  EXPECT_EQ(want_bounds.lo, got_bounds.lo);
  EXPECT_EQ(want_bounds.hi, got_bounds.hi);
  const Accel accel = build_accel(copy, BuildConfig{});
  const std::vector<Ray> rays = test::random_rays(4000, 5);
  for (Isa isa : test::supported_isas()) {
    SCOPED_TRACE(isa_name(isa));
    TraceOptions o;
    o.isa = isa;
    std::vector<Hit> want(rays.size());
    trace(accel, rays, want, o);
    std::vector<InstanceHit> got(rays.size());
    asset.scene().trace(rays, got, 0xFFFFFFFFu, o);
    std::vector<uint8_t> want_occ(rays.size()), got_occ(rays.size());
    occluded(accel, rays, want_occ, o);
    asset.scene().occluded(rays, got_occ, 0xFFFFFFFFu, o);
    size_t hits = 0;
    for (size_t i = 0; i < rays.size(); ++i) {
      ASSERT_EQ(want[i].hit(), got[i].hit()) << "ray " << i;
      ASSERT_EQ(want_occ[i], got_occ[i]) << "ray " << i;
      if (!want[i].hit()) continue;
      ++hits;
      ASSERT_EQ(got[i].instance_id, 0u);
      ASSERT_EQ(want[i].prim_id, got[i].prim_id) << "ray " << i;
      ASSERT_EQ(want[i].t, got[i].t) << "ray " << i;
      ASSERT_EQ(want[i].u, got[i].u) << "ray " << i;
      ASSERT_EQ(want[i].v, got[i].v) << "ray " << i;
    }
    EXPECT_GT(hits, rays.size() / 10);
    // A ray mask with no bit of the instance's: nothing is hit.
    std::vector<InstanceHit> none(rays.size());
    asset.scene().trace(rays, none, 0u, o);
    for (const InstanceHit& h : none) ASSERT_FALSE(h.hit());
  }
}

// Off the direct path (the instance moved, or a second instance): the TLAS kernels, checked
// against the flattened scene as every two-level test is.
TEST(Asset, MovedOrSecondInstanceLeavesTheDirectPath) {
  Asset asset = Asset::from_scene(test::random_soup(600, 0.2f, 4));
  InstancedScene& s = asset.scene();
  s.set_transform(0, Affine3::translation({0.5f, 0, 0}) * Affine3::rotation_y(20));
  s.commit();
  expect_matches_flattened(s, {0}, "moved");
  const InstanceId second = s.add_instance(s.instance_mesh(0), Affine3{});
  s.commit();
  expect_matches_flattened(s, {0, second}, "two instances");
}

TEST(Asset, LoadersAndUpdates) {
  Asset box = Asset::load("builtin:cornell_box");
  const Scene flat = load_scene("builtin:cornell_box");
  EXPECT_EQ(box.scene().instance_count(), flat.meshes.size());
  EXPECT_EQ(box.scene().materials().size(), flat.materials.size());
  EXPECT_FALSE(box.animated());
  const uint64_t g = box.scene().generation();
  box.update(1.0);  // static: nothing to pose, nothing committed
  EXPECT_EQ(box.scene().generation(), g);
  box.update(1.0, true);
  EXPECT_EQ(box.scene().generation(), g + 1);
  EXPECT_THROW(box.update(NAN), Error);
  EXPECT_THROW(Asset::load("/nonexistent/scene.obj"), Error);
  if (auto path = test::shared_scene("gltf_box_animated/BoxAnimated.gltf")) {
    Asset a = Asset::load(*path);
    EXPECT_TRUE(a.animated());
    EXPECT_GT(a.duration(), 0);
    const uint64_t before = a.scene().generation();
    a.update(0.7);
    EXPECT_EQ(a.scene().generation(), before + 1);
    EXPECT_FALSE(a.scene().materials().empty());
  }
}

}  // namespace
}  // namespace kestrel

namespace kestrel {
namespace {

// The glTF two-level path on a file made here (never skipped): a mesh shared by a node and
// its child, a morph target, and a clip moving the parent and the morph weight; against the
// flattening loader, the closed-form poses, and ray by ray against the flattened scene.
TEST(GltfInstances, SyntheticAnimatedFileFollowsItsClip) {
  const std::string path = test::write_animated_gltf("synthetic_animated.gltf");
  GltfInstances g = GltfInstances::load(path);
  EXPECT_EQ(g.mesh_count(), 2u);
  EXPECT_EQ(g.instance_count(), 3u);
  EXPECT_NEAR(g.duration(), 2.0, 1e-9);
  EXPECT_EQ(g.materials().front().name, "red");
  InstancedScene s;
  g.add_to(s);
  EXPECT_EQ(s.commit().blas_builds, 2u);
  const Scene flat0 = s.flatten();
  const Scene loaded = load_scene(path);  // the flattening loader poses at t = 0
  EXPECT_EQ(loaded.triangle_count(), flat0.triangle_count());
  const Bounds3 a = bounds_of(flat0), b = bounds_of(loaded);
  EXPECT_NEAR(a.lo.x, b.lo.x, 1e-5f);
  EXPECT_NEAR(a.hi.x, b.hi.x, 1e-5f);
  EXPECT_NEAR(a.hi.z, b.hi.z, 1e-5f);
  expect_matches_flattened(s, {0, 1, 2}, "synthetic t = 0");
  g.set_time(s, 1.0);  // halfway: parent +0.5 y (its child follows), morph weight 0.5
  const CommitStats st = s.commit();
  EXPECT_EQ(st.blas_refits + st.blas_builds, 1u);  // the morphing soup only
  const Scene flat1 = s.flatten();
  for (size_t m = 0; m < 2; ++m)  // the box under node 0 and under its child
    for (size_t i = 0; i < flat0.meshes[m].positions.size(); ++i)
      ASSERT_NEAR(flat1.meshes[m].positions[i].y, flat0.meshes[m].positions[i].y + 0.5f, 1e-5f);
  for (size_t i = 0; i < flat0.meshes[2].positions.size(); ++i)
    ASSERT_NEAR(flat1.meshes[2].positions[i].y, flat0.meshes[2].positions[i].y + 0.15f, 1e-5f);
  expect_matches_flattened(s, {0, 1, 2}, "synthetic t = 1");
  // As an Asset: animated, materials carried, update() poses and commits.
  Asset asset = Asset::load(path);
  EXPECT_TRUE(asset.animated());
  EXPECT_EQ(asset.scene().materials().front().name, "red");
  asset.update(1.0);
  EXPECT_NEAR(asset.bounds().hi.y, bounds_of(flat1).hi.y, 1e-5f);
}

// The instances file format on a file made here (the bunny grid's test needs the shared
// scenes): one mesh, sixteen transforms, flattened as the transforms say.
TEST(Instances, SyntheticInstancesFilePlacesOneMeshSixteenTimes) {
  std::string text = "# sx sy sz tx ty tz rot_y_deg\n";
  for (int i = 0; i < 16; ++i)
    text += fmt::format("{} {} {} {} 0 {} {}\n", 0.5 + 0.1 * (i % 3), 1, 0.5, 2 * (i % 4),
                        2 * (i / 4), 22.5 * i);
  const std::vector<Affine3> t =
      load_instance_transforms(test::write_temp_file("synthetic.instances.txt", text));
  ASSERT_EQ(t.size(), 16u);
  InstancedScene s;
  const TriangleMesh mesh = test::closed_sphere(2, {0, 0.5f, 0}, 0.4f).meshes[0];
  const MeshId m = s.add_mesh(mesh);
  std::vector<InstanceId> ids;
  for (const Affine3& a : t) ids.push_back(s.add_instance(m, a));
  const CommitStats stats = s.commit();
  EXPECT_EQ(stats.blas_builds, 1u);
  EXPECT_EQ(stats.instances, 16u);
  const Scene flat = s.flatten();
  for (size_t k = 0; k < 16; ++k) {
    const float rad = float(22.5 * double(k) * 3.14159265358979 / 180.0);
    const Vec3 p = mesh.positions[0], q = flat.meshes[k].positions[0];
    const float sx = 0.5f + 0.1f * float(k % 3);
    const Vec3 want{std::cos(rad) * sx * p.x + std::sin(rad) * 0.5f * p.z + 2.0f * float(k % 4),
                    p.y,
                    -std::sin(rad) * sx * p.x + std::cos(rad) * 0.5f * p.z + 2.0f * float(k / 4)};
    EXPECT_NEAR(q.x, want.x, 1e-4f) << k;
    EXPECT_NEAR(q.y, want.y, 1e-4f) << k;
    EXPECT_NEAR(q.z, want.z, 1e-4f) << k;
  }
  expect_matches_flattened(s, ids, "synthetic grid");
}

}  // namespace
}  // namespace kestrel
