// Traversal edge cases: watertightness on closed meshes, axis-parallel rays, tmin/tmax,
// NaN/Inf rays, and the triangle test against analytic answers.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>

#include "core/vec.h"
#include "geometry/triangle_intersect.h"
#include "kestrel/kestrel.h"
#include "support/oracles.h"

namespace kestrel {
namespace {

BuildConfig config_for(Builder b) {
  BuildConfig c;
  c.builder = b;
  return c;
}

TEST(Triangle, AnalyticHitDistanceAndBarycentrics) {
  const Triangle tri{{0, 0, 5}, {2, 0, 5}, {0, 2, 5}};
  const Ray ray{{0.5f, 0.25f, 0}, {0, 0, 2}};
  float t = 0, u = 0, v = 0;
  ASSERT_TRUE(intersect_triangle(WatertightRay(ray), tri, 0.0f, INFINITY, t, u, v));
  EXPECT_FLOAT_EQ(t, 2.5f);  // units of dir: |dir| = 2
  EXPECT_FLOAT_EQ(u, 0.25f);
  EXPECT_FLOAT_EQ(v, 0.125f);
  EXPECT_FALSE(
      intersect_triangle(WatertightRay(ray), tri, 0.0f, 2.5f, t, u, v));  // t must be < tmax
  EXPECT_FALSE(intersect_triangle(WatertightRay(ray), tri, 2.5f, INFINITY, t, u, v));  // and > tmin
  const Ray away{{0.5f, 0.25f, 0}, {0, 0, -1}};
  EXPECT_FALSE(intersect_triangle(WatertightRay(away), tri, 0.0f, INFINITY, t, u, v));
}

class Watertight : public ::testing::TestWithParam<Builder> {};

// Rays from outside aimed exactly at vertices and at points on shared edges of a closed
// mesh must hit it; rays from the centre must never escape. The outside origins lie within
// a cone about the outward normal, so the edge is never a silhouette edge (a ray that only
// grazes a silhouette may legitimately miss).
TEST_P(Watertight, RaysThroughEdgesAndVerticesNeverSlipThrough) {
  const Scene scene = test::closed_sphere(3, {0.3f, -0.2f, 0.1f}, 1.7f);
  const Accel accel = build_accel(scene, config_for(GetParam()));
  const TriangleMesh& mesh = scene.meshes[0];
  test::Rng rng{99};
  size_t rays = 0;
  for (size_t t = 0; t < mesh.triangle_count(); ++t) {
    for (int k = 0; k < 3; ++k) {
      const Vec3 a = mesh.positions[mesh.indices[3 * t + k]];
      const Vec3 b = mesh.positions[mesh.indices[3 * t + (k + 1) % 3]];
      for (float s : {0.0f, 0.5f, 0.25f, 1.0f / 3.0f}) {
        const Vec3 target = a + (b - a) * s;
        const Vec3 normal = normalize(target - Vec3{0.3f, -0.2f, 0.1f});
        const Vec3 outside = target + normalize(normal + rng.on_sphere() * 0.6f) * 3.0f;
        const Ray in{outside, target - outside};
        ASSERT_TRUE(intersect(accel, in).hit()) << "triangle " << t << " edge " << k << " s " << s;
        ASSERT_TRUE(intersect_any(accel, in).hit());
        const Ray out{{0.3f, -0.2f, 0.1f}, target - Vec3{0.3f, -0.2f, 0.1f}};
        ASSERT_TRUE(intersect(accel, out).hit())
            << "escaped through triangle " << t << " edge " << k;
        rays += 2;
      }
    }
  }
  EXPECT_GT(rays, 10000u);
}

TEST_P(Watertight, AxisAlignedBoxEdgesAndFaces) {
  // Axis-parallel rays along the box's edges and faces: slab tests see 0 * inf here.
  const Scene scene = test::closed_box({-1, -1, -1}, {1, 1, 1});
  const Accel accel = build_accel(scene, config_for(GetParam()));
  for (float x : {-1.0f, -0.5f, 0.0f, 1.0f})
    for (float y : {-1.0f, 0.0f, 0.25f, 1.0f}) {
      const Ray down{{x, y, 5}, {0, 0, -1}};
      const Hit h = intersect(accel, down);
      ASSERT_TRUE(h.hit()) << x << ", " << y;
      EXPECT_FLOAT_EQ(h.t, 4.0f);
      const Ray inside{{x * 0.5f, y * 0.5f, 0}, {0, 0, 1}};
      ASSERT_TRUE(intersect(accel, inside).hit());
      EXPECT_FLOAT_EQ(intersect(accel, inside).t, 1.0f);
    }
}

INSTANTIATE_TEST_SUITE_P(Builders, Watertight, ::testing::ValuesIn(test::all_builders()),
                         [](const auto& info) { return std::string(builder_name(info.param)); });

TEST(Rays, NonFiniteAndDegenerateRaysMiss) {
  const Accel accel = build_accel(test::closed_box({-1, -1, -1}, {1, 1, 1}), BuildConfig{});
  const float nan = std::numeric_limits<float>::quiet_NaN(),
              inf = std::numeric_limits<float>::infinity();
  const Ray bad[] = {
      {{nan, 0, 0}, {0, 0, 1}},
      {{0, 0, 0}, {nan, 0, 1}},
      {{0, 0, 0}, {0, 0, 0}},
      {{inf, 0, 0}, {-1, 0, 0}},
      {{0, 0, 0}, {0, inf, 0}},
      {{0, 0, 0}, {0, 0, 1}, nan, inf},
      {{0, 0, 0}, {0, 0, 1}, 0.0f, nan},
      {{0, 0, 0}, {0, 0, 1}, 2.0f, 1.0f},
  };
  for (const Ray& r : bad) {
    EXPECT_FALSE(intersect(accel, r).hit());
    EXPECT_FALSE(intersect_any(accel, r).hit());
  }
}

TEST(Rays, TminAndTmaxAreHonoured) {
  const Accel accel = build_accel(test::closed_box({-1, -1, -1}, {1, 1, 1}), BuildConfig{});
  const Ray r{{0.1f, 0.2f, -3}, {0, 0, 1}};
  EXPECT_FLOAT_EQ(intersect(accel, r).t, 2.0f);
  EXPECT_FLOAT_EQ(intersect(accel, Ray{r.org, r.dir, 2.5f, INFINITY}).t,
                  4.0f);  // skip the near face
  EXPECT_FALSE(intersect(accel, Ray{r.org, r.dir, 0.0f, 1.99f}).hit());
  EXPECT_FALSE(intersect(accel, Ray{r.org, r.dir, 4.01f, INFINITY}).hit());
  EXPECT_FALSE(intersect_any(accel, Ray{r.org, r.dir, 2.01f, 3.99f}).hit());
}

TEST(Trace, BatchEqualsSingleRaysForAnyThreadCount) {
  const Scene scene = test::random_soup(20000, 0.03f, 3);
  const Accel accel = build_accel(scene, BuildConfig{});
  const auto rays = test::random_rays(50000, 8);
  std::vector<Hit> one(rays.size()), many(rays.size());
  {
    ThreadLimit l(1);
    trace(accel, rays, one, false);
  }
  {
    ThreadLimit l(4);
    trace(accel, rays, many, false);
  }
  for (size_t i = 0; i < rays.size(); i += 97) {
    const Hit h = intersect(accel, rays[i]);
    ASSERT_EQ(one[i].prim_id, h.prim_id);
    ASSERT_EQ(one[i].t, h.t);
  }
  for (size_t i = 0; i < rays.size(); ++i) {
    ASSERT_EQ(one[i].prim_id, many[i].prim_id);
    ASSERT_EQ(one[i].t, many[i].t);
  }
}

}  // namespace
}  // namespace kestrel
