// Validation at the boundary: NaN/Inf vertices, out-of-range indices, degenerate triangles
// and empty meshes are counted; the bad triangles keep their ids but are never built.
#include <fmt/format.h>

#include "core/parallel.h"
#include "core/vec.h"
#include "geometry/triangle_classify.h"
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

void tally(std::span<const uint8_t> kind, SceneValidation& out) {
  ValidationReport& r = out.report;
  r.triangle_count = kind.size();
  out.valid.resize(kind.size());
  size_t count[256] = {};  // per class: a table, not a branch per triangle
  for (size_t i = 0; i < kind.size(); ++i) {
    out.valid[i] = kind[i] == tri_valid;
    ++count[kind[i]];
  }
  r.valid_triangle_count += count[tri_valid];
  r.nonfinite_triangle_count += count[tri_nonfinite];
  r.bad_index_triangle_count += count[tri_bad_index];
  r.degenerate_triangle_count +=
      kind.size() - count[tri_valid] - count[tri_nonfinite] - count[tri_bad_index];
}

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
      for (size_t i = b; i < e; ++i) kind[offset + i] = classify_triangle(mesh, i);
    });
    offset += n;
  }
  tally(kind, out);
  return out;
}

Bounds3 scene_bounds(const Scene& scene) {
  Bounds3 b;
  for (const TriangleMesh& m : scene.meshes)
    for (uint32_t i : m.indices)
      if (i < m.positions.size() && is_finite(m.positions[i])) extend(b, m.positions[i]);
  return b;
}

}  // namespace kestrel
