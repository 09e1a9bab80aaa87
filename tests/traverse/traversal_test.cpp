// Traversal edge cases: watertightness on closed meshes, axis-parallel rays, tmin/tmax,
// NaN/Inf rays (also inside coherent packets, through every kernel), and the triangle test
// against analytic answers.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <iterator>
#include <limits>
#include <string>
#include <vector>

#include "core/vec.h"
#include "geometry/triangle_intersect.h"
#include "kestrel/kestrel.h"
#include "support/oracles.h"
#include "traverse/accel_nodes.h"

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

TEST(Rays, UntraceableRaysMissInEveryKernel) {
  const Scene scene = test::random_soup(200, 0.3f, 1);
  const float nan = std::nanf(""), inf = INFINITY;
  const std::vector<Ray> rays = {{{nan, 0.5f, 0.5f}, {1, 0, 0}},
                                 {{0.5f, 0.5f, -1}, {0, 0, nan}},
                                 {{0.5f, 0.5f, -1}, {0, 0, 0}},
                                 {{inf, 0.5f, 0.5f}, {-1, 0, 0}},
                                 {{0.5f, 0.5f, -1}, {0, 0, 1}, 2.0f, 1.0f},  // tmin > tmax
                                 {{0.5f, 0.5f, -1}, {0, 0, 1}, 0.0f, nan}};
  // The same rays inside coherent packets (a grid of parallel rays, most of them hitting):
  // the kernels take batches unscanned and must give these a miss without disturbing their
  // packet's other rays (oracle: brute force, ray by ray).
  std::vector<Ray> mixed;
  for (int y = 0; y < 12; ++y)
    for (int x = 0; x < 16; ++x)
      mixed.push_back({{0.1f + 0.05f * float(x), 0.1f + 0.07f * float(y), -1}, {0.01f, 0.02f, 1}});
  // Some are the rays above; most are the packet's own rays made untraceable, so that they
  // share its direction signs and could take part in its frustum and its shared decisions.
  const size_t slots[] = {0, 5, 15, 16, 47, 100, 101, 191};
  for (size_t k = 0; k < std::size(slots); ++k) mixed[slots[k]] = rays[k % rays.size()];
  for (size_t i = 20; i < mixed.size(); i += 9) {
    Ray& r = mixed[i];
    switch (i % 5) {
      case 0:
        r.org.x = inf;
        break;
      case 1:
        r.org.y = -inf;
        break;
      case 2:
        r.tmin = 5.0f, r.tmax = 4.0f;
        break;
      case 3:
        r.tmax = nan;
        break;
      default:
        r.org.z = nan;
        break;
    }
  }
  const test::Soup soup = test::flatten(scene);
  std::vector<Hit> want(mixed.size());
  size_t hitting = 0;
  for (size_t i = 0; i < mixed.size(); ++i)
    hitting += (want[i] = intersect_brute_force(soup.triangles, soup.valid, mixed[i], false)).hit();
  ASSERT_GT(hitting, mixed.size() / 4);  // not vacuous
  for (Layout layout : {Layout::bvh2, Layout::bvh4, Layout::bvh8}) {
    const Accel a = test::build_layout(scene, Builder::binned, layout);
    for (Isa isa : test::supported_isas())
      for (const std::optional<bool> packets :
           {std::optional<bool>(), std::optional(false), std::optional(true)}) {
        SCOPED_TRACE(std::string(layout_name(layout)) + " " + isa_name(isa) + " packets " +
                     (packets ? std::to_string(*packets) : "auto"));
        TraceOptions opt;
        opt.isa = isa;
        opt.packets = packets;
        std::vector<Hit> hits(rays.size());
        trace(a, rays, hits, false, opt);
        for (const Hit& h : hits) EXPECT_FALSE(h.hit());
        trace(a, rays, hits, true, opt);
        for (const Hit& h : hits) EXPECT_FALSE(h.hit());
        // Filled with a hit first: every slot must be written.
        std::vector<Hit> got(mixed.size(), Hit{1.0f, 7, 0.0f, 0.0f});
        trace(a, mixed, got, false, opt);
        for (size_t i = 0; i < mixed.size(); ++i) {
          ASSERT_EQ(got[i].prim_id, want[i].prim_id) << "ray " << i;
          if (want[i].hit()) {
            ASSERT_EQ(got[i].t, want[i].t) << "ray " << i;
          }
        }
        std::fill(got.begin(), got.end(), Hit{1.0f, 7, 0.0f, 0.0f});
        trace(a, mixed, got, true, opt);
        for (size_t i = 0; i < mixed.size(); ++i)
          ASSERT_EQ(got[i].hit(), want[i].hit()) << "ray " << i << " (any hit)";
      }
  }
}

// is_traceable (SSE compares) is its definition, written here as the chain of tests it
// replaced: every combination of a normal, zero, negative zero, infinite and NaN value in each
// of the ray's eight floats.
TEST(Rays, TraceableTestIsTheDefinition) {
  const auto definition = [](const Ray& r) {
    const bool finite = std::isfinite(r.org.x) && std::isfinite(r.org.y) &&
                        std::isfinite(r.org.z) && std::isfinite(r.dir.x) &&
                        std::isfinite(r.dir.y) && std::isfinite(r.dir.z) && !std::isnan(r.tmin) &&
                        !std::isnan(r.tmax);
    return finite && (r.dir.x != 0.0f || r.dir.y != 0.0f || r.dir.z != 0.0f) && r.tmin <= r.tmax;
  };
  const float nan = std::nanf(""), inf = INFINITY;
  const float values[] = {0.5f, 0.0f, -0.0f, -2.0f, inf, -inf, nan};
  size_t traceable = 0, checked = 0;
  for (int slot = 0; slot < 8; ++slot)
    for (int other = 0; other < 8; ++other)
      for (const float v : values)
        for (const float w : values) {
          float f[8] = {0.5f, -1.0f, 2.0f, 0.0f, 0.0f, 1.0f, 0.0f, inf};
          f[slot] = v, f[other] = w;
          Ray r;
          std::memcpy(&r, f, sizeof f);
          ASSERT_EQ(is_traceable(r), definition(r))
              << "slot " << slot << " = " << v << ", slot " << other << " = " << w;
          traceable += definition(r), ++checked;
        }
  EXPECT_GT(traceable, checked / 4);  // both answers occur
  EXPECT_LT(traceable, checked);
}

}  // namespace
}  // namespace kestrel
