// Watertight ray-triangle intersection (Woop, Benthin & Wald, JCGT 2013).
// The ray is sheared so it runs along +z from the origin; edge functions are evaluated in
// 2D, falling back to double precision when one is exactly zero, so a ray through a shared
// edge or vertex hits at least one of the triangles sharing it. The hit distance is taken
// from the triangle's plane (see intersect_triangle).
#pragma once
#include <cmath>
#include <utility>

#include "kestrel/trace.h"

namespace kestrel {

/// Per-ray shear constants, computed once per ray.
struct WatertightRay {
  Vec3 org, dir;
  int kx, ky, kz;
  float sx, sy;

  explicit WatertightRay(const Ray& r) : org(r.org), dir(r.dir) {
    float ax = std::fabs(r.dir.x), ay = std::fabs(r.dir.y), az = std::fabs(r.dir.z);
    kz = ax >= ay ? (ax >= az ? 0 : 2) : (ay >= az ? 1 : 2);
    kx = kz == 2 ? 0 : kz + 1;
    ky = kx == 2 ? 0 : kx + 1;
    if (r.dir[kz] < 0.0f) std::swap(kx, ky);  // keep the winding independent of direction
    sx = r.dir[kx] / r.dir[kz];
    sy = r.dir[ky] / r.dir[kz];
  }
};

/// Intersects one triangle; on a hit at t > tmin writes t, u, v and returns true.
/// Every traversal kernel reproduces these operations bit for bit (see wide_kernels.inl).
inline bool watertight_hit(const WatertightRay& wr, const Triangle& tri, float tmin, float& t_out,
                           float& u_out, float& v_out) {
  const Vec3 a{tri.v0.x - wr.org.x, tri.v0.y - wr.org.y, tri.v0.z - wr.org.z};
  const Vec3 b{tri.v1.x - wr.org.x, tri.v1.y - wr.org.y, tri.v1.z - wr.org.z};
  const Vec3 c{tri.v2.x - wr.org.x, tri.v2.y - wr.org.y, tri.v2.z - wr.org.z};
  const float ax = a[wr.kx] - wr.sx * a[wr.kz], ay = a[wr.ky] - wr.sy * a[wr.kz];
  const float bx = b[wr.kx] - wr.sx * b[wr.kz], by = b[wr.ky] - wr.sy * b[wr.kz];
  const float cx = c[wr.kx] - wr.sx * c[wr.kz], cy = c[wr.ky] - wr.sy * c[wr.kz];
  float u = cx * by - cy * bx;
  float v = ax * cy - ay * cx;
  float w = bx * ay - by * ax;
  if (u == 0.0f || v == 0.0f || w == 0.0f) {
    u = float(double(cx) * by - double(cy) * bx);
    v = float(double(ax) * cy - double(ay) * cx);
    w = float(double(bx) * ay - double(by) * ax);
  }
  if ((u < 0.0f || v < 0.0f || w < 0.0f) && (u > 0.0f || v > 0.0f || w > 0.0f)) return false;
  const float det = u + v + w;
  if (det == 0.0f) return false;
  // The distance comes from the plane equation, t = n.(v0 - o) / n.d, not from Woop's
  // barycentric sum U*Az + V*Bz + W*Cz: on long, thin triangles hit close to the origin that
  // sum cancels large vertex distances and loses several digits (2% seen on a real scene),
  // while the plane distance stays accurate. The hit/miss decision above is unchanged, so
  // the test stays watertight. It is evaluated in the permuted axes (kx, ky, kz) so the SIMD
  // kernels reuse the vertex differences they already hold.
  const float ax_ = a[wr.kx], ay_ = a[wr.ky], az_ = a[wr.kz];
  const Vec3 e1{b[wr.kx] - ax_, b[wr.ky] - ay_, b[wr.kz] - az_};
  const Vec3 e2{c[wr.kx] - ax_, c[wr.ky] - ay_, c[wr.kz] - az_};
  const Vec3 n{e1.y * e2.z - e1.z * e2.y, e1.z * e2.x - e1.x * e2.z, e1.x * e2.y - e1.y * e2.x};
  const float n_dot_d = n.x * wr.dir[wr.kx] + n.y * wr.dir[wr.ky] + n.z * wr.dir[wr.kz];
  if (n_dot_d == 0.0f) return false;
  const float t = (n.x * ax_ + n.y * ay_ + n.z * az_) / n_dot_d;
  if (!(t > tmin)) return false;
  const float inv_det = 1.0f / det;
  t_out = t;
  // u, v, w are weights of vertices 0, 1, 2 (edge functions opposite each vertex).
  u_out = v * inv_det;
  v_out = w * inv_det;
  return true;
}

/// Intersects one triangle; on a hit in (tmin, t_best) writes t, u, v and returns true.
inline bool intersect_triangle(const WatertightRay& wr, const Triangle& tri, float tmin,
                               float t_best, float& t_out, float& u_out, float& v_out) {
  float t, u, v;
  if (!watertight_hit(wr, tri, tmin, t, u, v) || !(t < t_best)) return false;
  t_out = t;
  u_out = u;
  v_out = v;
  return true;
}

/// Closest-hit acceptance: a candidate at t <= best_t replaces the best hit when nearer, or
/// equally near with a smaller prim id (so ties resolve the same in every traversal order).
/// With no hit yet (best_id == invalid_id) best_t is the ray's tmax, which is exclusive.
inline bool closer_hit(float t, uint32_t id, float best_t, uint32_t best_id) {
  return t < best_t || (t == best_t && best_id != invalid_id && id < best_id);
}

/// A ray is traceable when every component is finite and the direction is non-zero.
inline bool is_traceable(const Ray& r) {
  bool finite = std::isfinite(r.org.x) && std::isfinite(r.org.y) && std::isfinite(r.org.z) &&
                std::isfinite(r.dir.x) && std::isfinite(r.dir.y) && std::isfinite(r.dir.z) &&
                !std::isnan(r.tmin) && !std::isnan(r.tmax);
  return finite && (r.dir.x != 0.0f || r.dir.y != 0.0f || r.dir.z != 0.0f) && r.tmin <= r.tmax;
}

}  // namespace kestrel
