// The spatial-split builder against its oracles: brute force ray by ray on scenes of long
// diagonal slivers (where splits are taken) in every layout and kernel, the SAH it promises
// over binned on such scenes, its reference budget, and bad input.
#include <gtest/gtest.h>

#include <cmath>
#include <string>
#include <vector>

#include "geometry/prim_ref.h"
#include "kestrel/error.h"
#include "kestrel/kestrel.h"
#include "support/oracles.h"
#include "traverse/accel_nodes.h"

namespace kestrel {
namespace {

// Long thin triangles crossing the unit cube diagonally, with random small ones around them:
// object splits cannot separate the slivers' boxes, spatial splits can.
Scene slivers(size_t long_count, size_t small_count, uint64_t seed) {
  Scene scene = test::random_soup(small_count, 0.05f, seed);
  TriangleMesh& mesh = scene.meshes[0];
  test::Rng rng(seed + 100);
  for (size_t i = 0; i < long_count; ++i) {
    const Vec3 a = rng.in_box({0, 0, 0}, {0.1f, 1, 0.1f});
    const Vec3 b = rng.in_box({0.9f, 0, 0.9f}, {1, 1, 1});
    const Vec3 c = a + Vec3{0.0f, 0.01f, 0.01f};
    const uint32_t base = uint32_t(mesh.positions.size());
    mesh.positions.insert(mesh.positions.end(), {a, b, c});
    mesh.indices.insert(mesh.indices.end(), {base, base + 1, base + 2});
  }
  return scene;
}

BuildConfig spatial_config() {
  BuildConfig c;
  c.builder = Builder::spatial;
  return c;
}

TEST(SpatialSplits, HitsMatchBruteForceInEveryLayoutAndKernel) {
  const Scene scene = slivers(400, 3000, 3);
  const test::Soup soup = test::flatten(scene);
  const auto rays = test::random_rays(6000, 17);
  for (Layout layout : {Layout::bvh2, Layout::bvh4, Layout::bvh8}) {
    BuildConfig config = spatial_config();
    config.layout = layout;
    const Accel accel = build_accel(scene, config);
    EXPECT_EQ(accel.prim_count, soup.triangles.size());
    for (Isa isa : test::supported_isas()) {
      TraceOptions options;
      options.isa = isa;
      std::vector<Hit> closest(rays.size()), any(rays.size());
      trace(accel, rays, closest, false, options);
      trace(accel, rays, any, true, options);
      size_t hits = 0;
      for (size_t i = 0; i < rays.size(); ++i) {
        SCOPED_TRACE(std::string(layout_name(layout)) + " " + isa_name(isa) + " ray " +
                     std::to_string(i));
        const Hit want = intersect_brute_force(soup.triangles, soup.valid, rays[i], false);
        ASSERT_EQ(closest[i].hit(), want.hit());
        ASSERT_EQ(any[i].hit(), want.hit());
        if (!want.hit()) continue;
        ++hits;
        ASSERT_EQ(closest[i].t, want.t);
      }
      EXPECT_GT(hits, rays.size() / 4);
    }
  }
}

TEST(SpatialSplits, CutTheSliversAndLowerTheSahWithinTheBudget) {
  const Scene scene = slivers(300, 2000, 5);
  SceneValidation validation;
  const Buffer<PrimRef> refs = validate_and_make_prim_refs(scene, validation);
  const Buffer<Triangle> triangles = gather_triangles(scene, validation);
  BuildConfig binned;
  binned.builder = Builder::binned;
  const BuildConfig spatial = spatial_config();
  const Bvh2 with_triangles = build_bvh(refs, triangles, spatial);
  const Bvh2 boxes_only = build_bvh(refs, spatial);
  ASSERT_EQ(validate_bvh(with_triangles, refs, spatial.max_leaf_size, true), "");
  ASSERT_EQ(validate_bvh(boxes_only, refs, spatial.max_leaf_size, true), "");
  // Splits were taken, within the budget (half the input again).
  EXPECT_GT(with_triangles.prim_ids.size(), refs.size() + refs.size() / 20);
  EXPECT_LE(with_triangles.prim_ids.size(), refs.size() + refs.size() / 2);
  const double sah_binned = compute_metrics(build_bvh(refs, binned), binned).sah_cost;
  const double sah_spatial = compute_metrics(with_triangles, spatial).sah_cost;
  const double sah_boxes = compute_metrics(boxes_only, spatial).sah_cost;
  EXPECT_LT(sah_spatial, 0.8 * sah_binned);
  EXPECT_LT(sah_spatial, sah_boxes);  // clipped triangles bound tighter than cut boxes
}

TEST(SpatialSplits, NoSplitsWhereObjectSplitsDoNotOverlap) {
  // A regular grid of small separate triangles: nothing to gain from cutting them.
  Scene grid;
  TriangleMesh mesh;
  for (int i = 0; i < 60; ++i)
    for (int j = 0; j < 60; ++j) {
      const uint32_t base = uint32_t(mesh.positions.size());
      const float x = float(i), z = float(j);
      mesh.positions.insert(mesh.positions.end(), {{x, 0, z}, {x + 0.5f, 0, z}, {x, 0, z + 0.5f}});
      mesh.indices.insert(mesh.indices.end(), {base, base + 1, base + 2});
    }
  grid.meshes.push_back(mesh);
  SceneValidation validation;
  const Buffer<PrimRef> refs = validate_and_make_prim_refs(grid, validation);
  const Bvh2 bvh = build_bvh(refs, gather_triangles(grid, validation), spatial_config());
  EXPECT_EQ(bvh.prim_ids.size(), refs.size());
}

TEST(SpatialSplits, LargeCoordinatesStayExact) {
  // Slivers scaled to 1e11 among triangles 2e12 across (the intersection test's cubic terms
  // stay finite), where the crossing points' rounding is 1e11 times the unit scene's: the
  // clipped parts must still cover every triangle.
  const float scale = 1e11f;
  Scene scene = slivers(200, 1500, 9);
  for (Vec3& p : scene.meshes[0].positions) p = p * scale;
  TriangleMesh& mesh = scene.meshes[0];
  for (int i = 0; i < 8; ++i) {
    const uint32_t base = uint32_t(mesh.positions.size());
    const float z = float(i) * 0.1f * scale, big = 10.0f * scale;
    mesh.positions.insert(mesh.positions.end(),
                          {{-big, -big, z}, {big, -big, z + 0.5f * scale}, {0, big, z}});
    mesh.indices.insert(mesh.indices.end(), {base, base + 1, base + 2});
  }
  const test::Soup soup = test::flatten(scene);
  std::vector<Ray> rays = test::random_rays(4000, 23);
  for (Ray& r : rays) {  // the same rays in the scaled scene: t scales with the origin
    r.org = r.org * scale;
    r.tmin *= scale;
    r.tmax *= scale;
  }
  for (Layout layout : {Layout::bvh2, Layout::bvh8}) {
    BuildConfig config = spatial_config();
    config.layout = layout;
    const Accel accel = build_accel(scene, config);
    std::vector<Hit> closest(rays.size());
    trace(accel, rays, closest, false, {});
    size_t hits = 0;
    for (size_t i = 0; i < rays.size(); ++i) {
      const Hit want = intersect_brute_force(soup.triangles, soup.valid, rays[i], false);
      ASSERT_EQ(closest[i].hit(), want.hit()) << layout_name(layout) << " ray " << i;
      if (want.hit()) {
        ++hits;
        ASSERT_EQ(closest[i].t, want.t) << layout_name(layout) << " ray " << i;
      }
    }
    EXPECT_GT(hits, rays.size() / 4);
  }
}

// Every point of every triangle (a barycentric grid, computed in double) lies in some leaf
// box holding the triangle, to a few ulps of rounding: the parts cover the triangles.
void expect_parts_cover_triangles(const Bvh2& bvh, std::span<const Triangle> triangles) {
  std::vector<std::vector<Bounds3>> boxes(triangles.size());
  for (const Bvh2Node& node : bvh.nodes)
    if (node.is_leaf())
      for (uint32_t k = node.index; k < node.index + node.count; ++k)
        boxes[bvh.prim_ids[k]].push_back({node.lo, node.hi});
  constexpr int steps = 12;
  for (size_t t = 0; t < triangles.size(); ++t) {
    const Triangle& tri = triangles[t];
    for (int i = 0; i <= steps; ++i)
      for (int j = 0; i + j <= steps; ++j) {
        const double u = double(i) / steps, v = double(j) / steps, w = 1.0 - u - v;
        double p[3];
        for (int a = 0; a < 3; ++a)
          p[a] = w * (&tri.v0.x)[a] + u * (&tri.v1.x)[a] + v * (&tri.v2.x)[a];
        bool covered = false;
        for (const Bounds3& b : boxes[t]) {
          bool inside = true;
          for (int a = 0; a < 3; ++a) {
            const double lo = (&b.lo.x)[a], hi = (&b.hi.x)[a];
            const double slack = 1e-6 * std::max(std::fabs(lo), std::fabs(hi));
            inside = inside && p[a] >= lo - slack && p[a] <= hi + slack;
          }
          covered = covered || inside;
        }
        ASSERT_TRUE(covered) << "triangle " << t << " point (" << u << ", " << v << ")";
      }
  }
}

TEST(SpatialSplits, PartsCoverTheirTriangles) {
  // (Float SAH costs, area x count, stay normal floats over this range of scales.)
  for (float scale : {1.0f, 1e-15f, 1e16f}) {
    Scene scene = slivers(300, 2000, 5);
    for (Vec3& p : scene.meshes[0].positions) p = p * scale;
    SceneValidation validation;
    const Buffer<PrimRef> refs = validate_and_make_prim_refs(scene, validation);
    const Buffer<Triangle> triangles = gather_triangles(scene, validation);
    const Bvh2 bvh = build_bvh(refs, triangles, spatial_config());
    ASSERT_GT(bvh.prim_ids.size(), refs.size()) << scale;  // splits were taken
    expect_parts_cover_triangles(bvh, triangles);
  }
}

TEST(SpatialSplits, TrianglesAcrossTheFloatRangeGiveAFiniteCoveringTree) {
  // Edges whose coordinate differences overflow float (and areas that do: the SAH degrades to
  // counts there): the boxes stay finite and cover the triangles.
  const Scene scene = test::soup_with_far_triangles(500, 40, 4);
  SceneValidation validation;
  const Buffer<PrimRef> refs = validate_and_make_prim_refs(scene, validation);
  const Buffer<Triangle> triangles = gather_triangles(scene, validation);
  const Bvh2 bvh = build_bvh(refs, triangles, spatial_config());
  ASSERT_EQ(validate_bvh(bvh, refs, 8, true), "");
  for (const Bvh2Node& node : bvh.nodes) {
    ASSERT_TRUE(std::isfinite(node.lo.x) && std::isfinite(node.lo.y) && std::isfinite(node.lo.z));
    ASSERT_TRUE(std::isfinite(node.hi.x) && std::isfinite(node.hi.y) && std::isfinite(node.hi.z));
  }
  expect_parts_cover_triangles(bvh, triangles);
}

TEST(SpatialSplits, QualityHighIsTheSpatialBuilder) {
  BuildConfig c;
  c.quality = BuildQuality::high;
  EXPECT_EQ(resolve_builder(c), Builder::spatial);
  EXPECT_EQ(builder_from_name("spatial"), Builder::spatial);
  EXPECT_STREQ(builder_name(Builder::spatial), "spatial");
}

TEST(SpatialSplits, TrianglesMustCoverThePrimIds) {
  const Scene scene = test::random_soup(50, 0.1f, 1);
  SceneValidation validation;
  const Buffer<PrimRef> refs = validate_and_make_prim_refs(scene, validation);
  Buffer<Triangle> triangles = gather_triangles(scene, validation);
  triangles.resize(10);
  EXPECT_THROW(build_bvh(refs, triangles, spatial_config()), Error);
}

}  // namespace
}  // namespace kestrel
