// Two-level scenes against their flattened copies (one BVH over world-space triangles), ray
// by ray: the oracle the instance and asset tests share.
#pragma once
#include <gtest/gtest.h>

#include <cmath>
#include <string>
#include <vector>

#include "core/vec.h"
#include "kestrel/kestrel.h"
#include "support/oracles.h"

namespace kestrel::test_two_level {

inline Bounds3 bounds_of(const Scene& s) {
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
inline std::vector<Ray> rays_through(const Scene& scene, size_t n, uint64_t seed) {
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
inline Fixture make_fixture() {
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
inline Located locate(const Scene& flat, uint32_t gid) {
  uint32_t inst = 0;
  for (const TriangleMesh& m : flat.meshes) {
    if (gid < m.triangle_count()) return {inst, gid};
    gid -= uint32_t(m.triangle_count());
    ++inst;
  }
  return {invalid_id, invalid_id};
}

inline void expect_matches_flattened(const InstancedScene& scene,
                                     const std::vector<InstanceId>& ids, const std::string& what) {
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

}  // namespace kestrel::test_two_level
