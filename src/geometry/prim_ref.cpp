#include "geometry/prim_ref.h"

#include "core/parallel.h"
#include "core/vec.h"

namespace kestrel {

namespace {
// Visits (global id, mesh, local triangle) in parallel chunks, mesh by mesh.
template <class F>
void for_each_triangle(const Scene& scene, F&& f) {
  size_t offset = 0;
  for (const TriangleMesh& mesh : scene.meshes) {
    size_t n = mesh.triangle_count();
    parallel_for(0, n, 16384, [&](size_t b, size_t e) {
      for (size_t i = b; i < e; ++i) f(offset + i, mesh, i);
    });
    offset += n;
  }
}
}  // namespace

std::vector<PrimRef> make_prim_refs(const Scene& scene, const SceneValidation& validation) {
  // Exclusive scan of validity gives each valid triangle its slot, independent of threads.
  const size_t total = validation.valid.size();
  std::vector<uint32_t> slot(total);
  uint32_t running = 0;
  for (size_t i = 0; i < total; ++i) {
    slot[i] = running;
    running += validation.valid[i];
  }
  std::vector<PrimRef> refs(running);
  for_each_triangle(scene, [&](size_t gid, const TriangleMesh& mesh, size_t t) {
    if (!validation.valid[gid]) return;
    const uint32_t* idx = &mesh.indices[3 * t];
    Bounds3 b;
    extend(b, mesh.positions[idx[0]]);
    extend(b, mesh.positions[idx[1]]);
    extend(b, mesh.positions[idx[2]]);
    PrimRef& r = refs[slot[gid]];
    r.lo = b.lo;
    r.hi = b.hi;
    r.prim_id = static_cast<uint32_t>(gid);
  });
  return refs;
}

std::vector<Triangle> gather_triangles(const Scene& scene, const SceneValidation& validation) {
  std::vector<Triangle> tris(validation.valid.size());
  for_each_triangle(scene, [&](size_t gid, const TriangleMesh& mesh, size_t t) {
    if (!validation.valid[gid]) return;
    const uint32_t* idx = &mesh.indices[3 * t];
    tris[gid] = {mesh.positions[idx[0]], mesh.positions[idx[1]], mesh.positions[idx[2]]};
  });
  return tris;
}

}  // namespace kestrel
