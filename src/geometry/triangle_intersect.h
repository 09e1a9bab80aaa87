// Watertight ray-triangle intersection (Woop, Benthin & Wald, JCGT 2013).
// The ray is sheared so it runs along +z from the origin; edge functions are evaluated in
// 2D, falling back to double precision when one is exactly zero, so a ray through a shared
// edge or vertex hits at least one of the triangles sharing it. The hit distance is taken
// from the triangle's plane (see intersect_triangle).
#pragma once
#include <emmintrin.h>

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

/// A ray is traceable when every component is finite (tmin and tmax may be infinite, not NaN),
/// the direction is non-zero and tmin <= tmax. In SSE compares and one test rather than a chain
/// of branches: the ray-stream scan (batches.h) runs it on every ray of its batches. The ray's
/// floats are read as [org.x org.y org.z dir.x] and [dir.y dir.z tmin tmax]. (Included by
/// baseline-ISA files only, as every inline function the kernels' callers share.)
inline bool is_traceable(const Ray& r) {
  static_assert(sizeof(Ray) == 8 * sizeof(float), "Ray: org, dir, tmin, tmax");
  const float* f = &r.org.x;
  const __m128 a = _mm_loadu_ps(f), b = _mm_loadu_ps(f + 4);
  const __m128 magnitude = _mm_castsi128_ps(_mm_set1_epi32(0x7FFFFFFF));
  const __m128 inf = _mm_set1_ps(__builtin_inff()), zero = _mm_setzero_ps();
  // a: every lane finite. b: dir.y, dir.z finite; tmin <= tmax (false with a NaN); tmax
  // ordered. The direction: some component non-zero.
  const int finite_a = _mm_movemask_ps(_mm_cmplt_ps(_mm_and_ps(a, magnitude), inf));
  const int finite_b = _mm_movemask_ps(_mm_cmplt_ps(_mm_and_ps(b, magnitude), inf));
  const int ordered_b =
      _mm_movemask_ps(_mm_cmple_ps(b, _mm_shuffle_ps(b, b, _MM_SHUFFLE(3, 3, 1, 0))));
  const int nonzero =
      (_mm_movemask_ps(_mm_cmpneq_ps(a, zero)) & 8) | (_mm_movemask_ps(_mm_cmpneq_ps(b, zero)) & 3);
  const int all = finite_a << 4 | (finite_b & 3) | (ordered_b & 0xC) | (nonzero != 0) << 8;
  return all == 0x1FF;
}

}  // namespace kestrel
