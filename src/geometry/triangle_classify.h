// Per-triangle validity, shared by validate_scene() and the fused validation + PrimRef pass.
#pragma once
#include <cstdint>
#include <span>

#include "core/vec.h"
#include "kestrel/scene.h"

namespace kestrel {

enum : uint8_t { tri_valid = 1, tri_nonfinite = 2, tri_bad_index = 3, tri_degenerate = 4 };

/// Classifies triangle t of the mesh: indices in range, finite vertices, non-zero area.
inline uint8_t classify_triangle(const TriangleMesh& mesh, size_t t) {
  const size_t vertex_count = mesh.positions.size();
  const uint32_t* idx = &mesh.indices[3 * t];
  if (idx[0] >= vertex_count || idx[1] >= vertex_count || idx[2] >= vertex_count)
    return tri_bad_index;
  const Vec3 a = mesh.positions[idx[0]], b = mesh.positions[idx[1]], c = mesh.positions[idx[2]];
  if (!is_finite(a) || !is_finite(b) || !is_finite(c)) return tri_nonfinite;
  // Exactly zero area (repeated or collinear vertices): no ray can hit it. Double precision,
  // so tiny but valid triangles are not thrown away by float underflow.
  const double ux = double(b.x) - a.x, uy = double(b.y) - a.y, uz = double(b.z) - a.z;
  const double vx = double(c.x) - a.x, vy = double(c.y) - a.y, vz = double(c.z) - a.z;
  if (uy * vz - uz * vy == 0.0 && uz * vx - ux * vz == 0.0 && ux * vy - uy * vx == 0.0)
    return tri_degenerate;
  return tri_valid;
}

/// Fills the validity flags and counts of `out` from per-triangle classes.
void tally(std::span<const uint8_t> kind, SceneValidation& out);

}  // namespace kestrel
