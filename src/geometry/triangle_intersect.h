// Watertight ray-triangle intersection (Woop, Benthin & Wald, JCGT 2013).
// The ray is sheared so it runs along +z from the origin; edge functions are evaluated in
// 2D, falling back to double precision when one is exactly zero, so a ray through a shared
// edge or vertex hits at least one of the triangles sharing it.
#pragma once
#include <cmath>
#include <utility>

#include "kestrel/trace.h"

namespace kestrel {

/// Per-ray shear constants, computed once per ray.
struct WatertightRay {
  Vec3 org;
  int kx, ky, kz;
  float sx, sy, sz;

  explicit WatertightRay(const Ray& r) : org(r.org) {
    float ax = std::fabs(r.dir.x), ay = std::fabs(r.dir.y), az = std::fabs(r.dir.z);
    kz = ax >= ay ? (ax >= az ? 0 : 2) : (ay >= az ? 1 : 2);
    kx = kz == 2 ? 0 : kz + 1;
    ky = kx == 2 ? 0 : kx + 1;
    if (r.dir[kz] < 0.0f) std::swap(kx, ky);  // keep the winding independent of direction
    sx = r.dir[kx] / r.dir[kz];
    sy = r.dir[ky] / r.dir[kz];
    sz = 1.0f / r.dir[kz];
  }
};

/// Intersects one triangle; on a hit in (tmin, t_best) writes t, u, v and returns true.
inline bool intersect_triangle(const WatertightRay& wr, const Triangle& tri, float tmin,
                               float t_best, float& t_out, float& u_out, float& v_out) {
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
  const float az = wr.sz * a[wr.kz], bz = wr.sz * b[wr.kz], cz = wr.sz * c[wr.kz];
  const float t_scaled = u * az + v * bz + w * cz;
  const float inv_det = 1.0f / det;
  const float t = t_scaled * inv_det;
  if (!(t > tmin && t < t_best)) return false;
  t_out = t;
  // u, v, w are weights of vertices 0, 1, 2 (edge functions opposite each vertex).
  u_out = v * inv_det;
  v_out = w * inv_det;
  return true;
}

/// A ray is traceable when every component is finite and the direction is non-zero.
inline bool is_traceable(const Ray& r) {
  bool finite = std::isfinite(r.org.x) && std::isfinite(r.org.y) && std::isfinite(r.org.z) &&
                std::isfinite(r.dir.x) && std::isfinite(r.dir.y) && std::isfinite(r.dir.z) &&
                !std::isnan(r.tmin) && !std::isnan(r.tmax);
  return finite && (r.dir.x != 0.0f || r.dir.y != 0.0f || r.dir.z != 0.0f) && r.tmin <= r.tmax;
}

}  // namespace kestrel
