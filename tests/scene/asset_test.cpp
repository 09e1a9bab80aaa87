// Assets (the one scene model: a file as a material-carrying InstancedScene) and synthetic
// two-level files (an animated glTF, an instances file), against the single-level Accel and
// the flattened scene.
#include <gtest/gtest.h>

#include <fmt/format.h>

#include <cmath>

#include "core/vec.h"
#include "kestrel/error.h"
#include "kestrel/kestrel.h"
#include "support/oracles.h"

#include "scene/flattened_oracle.h"

namespace kestrel {
namespace {

using namespace test_two_level;

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

// Skinning (glTF skins, linear blend): a triangle on two joints, the second 1 along x and
// turned 90 degrees about z by the clip from t = 1 on (keys at 0, 1, 2). Vertex 1 (on joint 1) goes
// from (2, 0, 0) to (1, 1, 0); vertex 2, weighted 1/4 and 3/4, to 1/4 (2, 1, 0) + 3/4 (0, 1, 0);
// the skinned mesh's own node (moved 5 along x) does not place it.
TEST(GltfInstances, SkinnedTriangleFollowsItsJoints) {
  const std::string path = test::write_temp_file(
      "skinned.gltf",
      R"({
    "asset": {"version": "2.0"}, "scene": 0, "scenes": [{"nodes": [0, 1]}],
    "nodes": [{"mesh": 0, "skin": 0, "translation": [5, 0, 0]}, {"children": [2]},
              {"translation": [1, 0, 0]}],
    "skins": [{"joints": [1, 2], "inverseBindMatrices": 3}],
    "meshes": [{"primitives": [{"attributes": {"POSITION": 0, "JOINTS_0": 1, "WEIGHTS_0": 2}}]}],
    "animations": [{"channels": [{"sampler": 0, "target": {"node": 2, "path": "rotation"}}],
                    "samplers": [{"input": 4, "output": 5}]}],
    "buffers": [{"byteLength": 284, "uri": "data:application/octet-stream;base64,)" +
          std::string(
              "AAAAAAAAAAAAAAAAAAAAQAAAAAAAAAAAAAAAQAAAgD8AAAAAAAAAAAEAAAAAAQAAAACAPwAAAAAAAAAAAAAA"
              "AAAAgD8AAAAAAAAAAAAAAAAAAIA+AABAPwAAAAAAAAAAAACAPwAAAAAAAAAAAAAAAAAAAAAAAIA/"
              "AAAAAAAAAAAAAAAAAAAAAAAAgD8AAAAAAAAAAAAAAAAAAAAAAACAPwAAgD8AAAAAAAAAAAAAAAAAAAAAAACA"
              "PwAAAAAAAAAAAAAAAAAAAAAAAIA/"
              "AAAAAAAAgL8AAAAAAAAAAAAAgD8AAAAAAACAPwAAAEAAAAAAAAAAAAAAAAAAAIA/AAAAAAAAAADzBDU/"
              "8wQ1PwAAAAAAAAAA8wQ1P/MENT8=") +
          R"("}],
    "bufferViews": [{"buffer": 0, "byteOffset": 0, "byteLength": 36},
                    {"buffer": 0, "byteOffset": 36, "byteLength": 12},
                    {"buffer": 0, "byteOffset": 48, "byteLength": 48},
                    {"buffer": 0, "byteOffset": 96, "byteLength": 128},
                    {"buffer": 0, "byteOffset": 224, "byteLength": 12},
                    {"buffer": 0, "byteOffset": 236, "byteLength": 48}],
    "accessors": [{"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3",
                   "min": [0, 0, 0], "max": [2, 1, 0]},
                  {"bufferView": 1, "componentType": 5121, "count": 3, "type": "VEC4"},
                  {"bufferView": 2, "componentType": 5126, "count": 3, "type": "VEC4"},
                  {"bufferView": 3, "componentType": 5126, "count": 2, "type": "MAT4"},
                  {"bufferView": 4, "componentType": 5126, "count": 3, "type": "SCALAR",
                   "min": [0], "max": [2]},
                  {"bufferView": 5, "componentType": 5126, "count": 3, "type": "VEC4"}]})");
  Asset asset = Asset::load(path);
  EXPECT_TRUE(asset.animated());
  auto expect_at = [&](double t, std::initializer_list<Vec3> want) {
    asset.update(t);
    const Scene flat = asset.scene().flatten();
    ASSERT_EQ(flat.meshes.size(), 1u);
    size_t i = 0;
    for (const Vec3& w : want) {
      const Vec3 p = flat.meshes[0].positions[i++];
      EXPECT_NEAR(p.x, w.x, 1e-5f) << "t " << t << " vertex " << i - 1;
      EXPECT_NEAR(p.y, w.y, 1e-5f) << "t " << t << " vertex " << i - 1;
      EXPECT_NEAR(p.z, w.z, 1e-5f) << "t " << t << " vertex " << i - 1;
    }
  };
  expect_at(0.0, {{0, 0, 0}, {2, 0, 0}, {2, 1, 0}});
  expect_at(1.0, {{0, 0, 0}, {1, 1, 0}, {0.5f, 1, 0}});
  const float c = std::sqrt(0.5f);  // halfway: 45 degrees (slerp)
  expect_at(0.5, {{0, 0, 0}, {1 + c, c, 0}, {1.25f, 0.25f + 1.5f * c, 0}});
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
