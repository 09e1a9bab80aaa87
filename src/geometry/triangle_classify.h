// Per-triangle validity, shared by validate_scene() and the fused validation + PrimRef pass.
#pragma once
#include <xmmintrin.h>

#include <cstdint>
#include <span>

#include "core/vec.h"
#include "kestrel/scene.h"

namespace kestrel {

enum : uint8_t { tri_valid = 1, tri_nonfinite = 2, tri_bad_index = 3, tri_degenerate = 4 };

/// Finite vertices and a non-zero area: tri_valid, tri_nonfinite or tri_degenerate.
inline uint8_t classify_vertices(const Vec3& a, const Vec3& b, const Vec3& c) {
  // x - x is NaN exactly when x is infinite or NaN: the nine coordinates in three SSE ops.
  const __m128 va = _mm_setr_ps(a.x, a.y, a.z, 0.0f), vb = _mm_setr_ps(b.x, b.y, b.z, 0.0f),
               vc = _mm_setr_ps(c.x, c.y, c.z, 0.0f);
  const __m128 d =
      _mm_add_ps(_mm_add_ps(_mm_sub_ps(va, va), _mm_sub_ps(vb, vb)), _mm_sub_ps(vc, vc));
  if (_mm_movemask_ps(_mm_cmpunord_ps(d, d)) != 0) return tri_nonfinite;
  // Exactly zero area (repeated or collinear vertices): no ray can hit it. Double precision,
  // so tiny but valid triangles are not thrown away by float underflow.
  const double ux = double(b.x) - a.x, uy = double(b.y) - a.y, uz = double(b.z) - a.z;
  const double vx = double(c.x) - a.x, vy = double(c.y) - a.y, vz = double(c.z) - a.z;
  if (uy * vz - uz * vy == 0.0 && uz * vx - ux * vz == 0.0 && ux * vy - uy * vx == 0.0)
    return tri_degenerate;
  return tri_valid;
}

/// Whether triangle t's three indices address vertices of the mesh.
inline bool indices_in_range(const TriangleMesh& mesh, size_t t) {
  const size_t vertex_count = mesh.positions.size();
  const uint32_t* idx = &mesh.indices[3 * t];
  return idx[0] < vertex_count && idx[1] < vertex_count && idx[2] < vertex_count;
}

/// Classifies triangle t of the mesh: indices in range, finite vertices, non-zero area.
inline uint8_t classify_triangle(const TriangleMesh& mesh, size_t t) {
  if (!indices_in_range(mesh, t)) return tri_bad_index;
  const uint32_t* idx = &mesh.indices[3 * t];
  return classify_vertices(mesh.positions[idx[0]], mesh.positions[idx[1]], mesh.positions[idx[2]]);
}

/// Fills the validity flags and counts of `out` from per-triangle classes.
void tally(std::span<const uint8_t> kind, SceneValidation& out);

}  // namespace kestrel
