// Validation at the boundary: NaN/Inf vertices, out-of-range indices, degenerate triangles
// and empty meshes are counted; the bad triangles keep their ids but are never built.
#include <fmt/format.h>

#include "core/parallel.h"
#include "core/vec.h"
#include "kestrel/scene.h"

namespace kestrel {

size_t Scene::triangle_count() const {
  size_t n = 0;
  for (const TriangleMesh& m : meshes) n += m.triangle_count();
  return n;
}

std::string ValidationReport::summary() const {
  return fmt::format(
      "{} triangles: {} valid, {} non-finite, {} bad index, {} degenerate; {} empty meshes",
      triangle_count, valid_triangle_count, nonfinite_triangle_count, bad_index_triangle_count,
      degenerate_triangle_count, empty_mesh_count);
}

namespace {
enum : uint8_t { tri_valid = 1, tri_nonfinite = 2, tri_bad_index = 3, tri_degenerate = 4 };

uint8_t classify(const TriangleMesh& mesh, size_t t) {
  const size_t vertex_count = mesh.positions.size();
  const uint32_t* idx = &mesh.indices[3 * t];
  if (idx[0] >= vertex_count || idx[1] >= vertex_count || idx[2] >= vertex_count) return tri_bad_index;
  Vec3 a = mesh.positions[idx[0]], b = mesh.positions[idx[1]], c = mesh.positions[idx[2]];
  if (!is_finite(a) || !is_finite(b) || !is_finite(c)) return tri_nonfinite;
  Vec3 n = cross(b - a, c - a);
  // Exactly zero area (repeated or collinear vertices): no ray can hit it. Compare in double
  // so tiny but valid triangles are not thrown away by float underflow.
  double nx = double(b.y - a.y) * (c.z - a.z) - double(b.z - a.z) * (c.y - a.y);
  double ny = double(b.z - a.z) * (c.x - a.x) - double(b.x - a.x) * (c.z - a.z);
  double nz = double(b.x - a.x) * (c.y - a.y) - double(b.y - a.y) * (c.x - a.x);
  (void)n;
  if (nx == 0.0 && ny == 0.0 && nz == 0.0) return tri_degenerate;
  return tri_valid;
}
}  // namespace

SceneValidation validate_scene(const Scene& scene) {
  SceneValidation out;
  const size_t total = scene.triangle_count();
  out.valid.assign(total, 0);
  std::vector<uint8_t> kind(total, 0);
  size_t offset = 0;
  for (const TriangleMesh& mesh : scene.meshes) {
    const size_t n = mesh.triangle_count();
    if (n == 0) ++out.report.empty_mesh_count;
    parallel_for(0, n, 16384, [&](size_t b, size_t e) {
      for (size_t i = b; i < e; ++i) kind[offset + i] = classify(mesh, i);
    });
    offset += n;
  }
  ValidationReport& r = out.report;
  r.triangle_count = total;
  for (size_t i = 0; i < total; ++i) {
    switch (kind[i]) {
      case tri_valid: out.valid[i] = 1; ++r.valid_triangle_count; break;
      case tri_nonfinite: ++r.nonfinite_triangle_count; break;
      case tri_bad_index: ++r.bad_index_triangle_count; break;
      default: ++r.degenerate_triangle_count; break;
    }
  }
  return out;
}

}  // namespace kestrel
