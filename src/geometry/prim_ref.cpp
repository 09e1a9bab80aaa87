#include "geometry/prim_ref.h"

#include <algorithm>
#include <mutex>

#include "core/parallel.h"
#include "core/vec.h"
#include "geometry/triangle_classify.h"

namespace kestrel {

namespace {

// Triangles reference vertices in arbitrary order (scanned and exported meshes often
// scramble them), so vertex reads miss the caches; asking for the vertices of the triangle
// `prefetch_distance` ahead overlaps those misses.
constexpr size_t prefetch_distance = 16;

inline void prefetch_vertices(const TriangleMesh& mesh, size_t t) {
  const uint32_t* idx = &mesh.indices[3 * t];
  const size_t vertex_count = mesh.positions.size();
  for (int k = 0; k < 3; ++k)
    if (idx[k] < vertex_count) __builtin_prefetch(&mesh.positions[idx[k]]);
}

// Visits the triangles in parallel chunks, mesh by mesh: chunk(f) runs on a chunk's thread
// with visit(f), which calls f(global id, mesh, local triangle) for each of its triangles
// (the vertices of the triangle `prefetch_distance` on prefetched).
template <class Chunk>
void for_each_triangle_chunk(const Scene& scene, Chunk&& chunk) {
  size_t offset = 0;
  for (const TriangleMesh& mesh : scene.meshes) {
    const size_t n = mesh.triangle_count();
    parallel_for(0, n, 16384, [&](size_t b, size_t e) {
      chunk([&](auto&& f) {
        for (size_t i = b; i < e; ++i) {
          if (i + prefetch_distance < e) prefetch_vertices(mesh, i + prefetch_distance);
          f(offset + i, mesh, i);
        }
      });
    });
    offset += n;
  }
}

// Visits (global id, mesh, local triangle) in parallel chunks, mesh by mesh.
template <class F>
void for_each_triangle(const Scene& scene, F&& f) {
  for_each_triangle_chunk(scene, [&](auto&& visit) { visit(f); });
}

PrimRef triangle_ref(const TriangleMesh& mesh, size_t t, uint32_t gid) {
  const uint32_t* idx = &mesh.indices[3 * t];
  const Vec3 a = mesh.positions[idx[0]], b = mesh.positions[idx[1]], c = mesh.positions[idx[2]];
  PrimRef r;
  r.lo = min(min(a, b), c);
  r.hi = max(max(a, b), c);
  r.prim_id = gid;
  return r;
}

// Slot of each valid triangle among the valid ones (exclusive scan), and their count.
size_t valid_slots(std::span<const uint8_t> valid, std::vector<uint32_t>& slot) {
  slot.resize(valid.size());
  uint32_t running = 0;
  for (size_t i = 0; i < valid.size(); ++i) {
    slot[i] = running;
    running += valid[i];
  }
  return running;
}

}  // namespace

Buffer<PrimRef> make_prim_refs(const Scene& scene, const SceneValidation& validation) {
  std::vector<uint32_t> slot;
  Buffer<PrimRef> refs(valid_slots(validation.valid, slot));
  for_each_triangle(scene, [&](size_t gid, const TriangleMesh& mesh, size_t t) {
    if (validation.valid[gid]) refs[slot[gid]] = triangle_ref(mesh, t, uint32_t(gid));
  });
  return refs;
}

Buffer<PrimRef> validate_and_make_prim_refs(const Scene& scene, SceneValidation& validation,
                                            Bounds3* centroids) {
  const size_t total = scene.triangle_count();
  std::vector<uint8_t> kind(total);
  // Every triangle's ref at its global id, then the valid ones compacted forward in place
  // (slot <= id, so nothing is overwritten before it is read).
  Buffer<PrimRef> refs(total);
  for (const TriangleMesh& mesh : scene.meshes)
    if (mesh.triangle_count() == 0) ++validation.report.empty_mesh_count;
  // The valid refs' centroid bounds, per chunk and then merged (min and max: the same result
  // in any order, so for any thread count).
  Bounds3 cb;
  std::mutex cb_mutex;
  for_each_triangle_chunk(scene, [&](auto&& visit) {
    Bounds3 local;
    visit([&](size_t gid, const TriangleMesh& mesh, size_t t) {
      kind[gid] = classify_triangle(mesh, t);
      if (kind[gid] != tri_valid) return;
      refs[gid] = triangle_ref(mesh, t, uint32_t(gid));
      extend(local, refs[gid].lo + refs[gid].hi);
    });
    const std::lock_guard<std::mutex> lock(cb_mutex);
    extend(cb, local);
  });
  if (centroids) *centroids = cb;
  tally(kind, validation);
  if (validation.report.valid_triangle_count == total) return refs;  // the common case
  size_t valid = 0;
  for (size_t i = 0; i < total; ++i)
    if (validation.valid[i]) refs[valid++] = refs[i];
  refs.resize(valid);
  return refs;
}

Buffer<Triangle> gather_triangles(const Scene& scene, const SceneValidation& validation) {
  Buffer<Triangle> tris(validation.valid.size());
  for_each_triangle(scene, [&](size_t gid, const TriangleMesh& mesh, size_t t) {
    if (!validation.valid[gid]) {
      tris[gid] = Triangle{};
      return;
    }
    const uint32_t* idx = &mesh.indices[3 * t];
    tris[gid] = {mesh.positions[idx[0]], mesh.positions[idx[1]], mesh.positions[idx[2]]};
  });
  return tris;
}

Buffer<Triangle> gather_triangles(const Scene& scene, std::span<const uint32_t> prim_ids) {
  const TrianglesById source(scene, prim_ids);
  Buffer<Triangle> tris(prim_ids.size());
  parallel_for(0, prim_ids.size(), 16384, [&](size_t b, size_t e) {
    for (size_t i = b; i < e; ++i) tris[i] = source.at(i);
  });
  return tris;
}

Buffer<Triangle> triangles_for_builder(const Scene& scene, const SceneValidation& validation,
                                       Builder builder) {
  return builder == Builder::spatial ? gather_triangles(scene, validation) : Buffer<Triangle>();
}

}  // namespace kestrel
