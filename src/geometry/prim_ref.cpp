#include "geometry/prim_ref.h"

#include <immintrin.h>

#include <algorithm>
#include <limits>
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

// Visits the triangles in parallel chunks of the global ids (a chunk may span meshes: scenes
// of many small meshes run in parallel too): chunk(f) runs on a chunk's thread with visit(f),
// which calls f(global id, mesh, local triangle) for each of its triangles (the vertices of
// the triangle `prefetch_distance` on in the same mesh prefetched).
template <class Chunk>
void for_each_triangle_chunk(const Scene& scene, Chunk&& chunk) {
  const MeshStarts starts(scene);
  parallel_for(0, starts.total(), 16384, [&](size_t b, size_t e) {
    chunk([&](auto&& f) {
      for (size_t g = b, m = starts.mesh_of(b); g < e; ++m) {
        const TriangleMesh& mesh = scene.meshes[m];
        const size_t first = starts.start(m), end = std::min(e, starts.start(m + 1));
        for (size_t i = g - first, n = end - first; i < n; ++i) {
          if (i + prefetch_distance < n) prefetch_vertices(mesh, i + prefetch_distance);
          f(first + i, mesh, i);
        }
        g = end;
      }
    });
  });
}

// Visits (global id, mesh, local triangle) in parallel chunks.
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

// classify_triangle and triangle_ref in one, the indices and vertices read once: writes the
// reference when the triangle is valid and grows the centroid bounds [cent_lo, cent_hi] by
// lo + hi. The same values as triangle_ref: MINPS(b, a) is std::min(a, b) (b < a ? b : a) and
// MAXPS(b, a) is std::max(a, b), signed zeros included.
inline uint8_t classify_and_ref(const TriangleMesh& mesh, size_t t, uint32_t gid, PrimRef& out,
                                __m128& cent_lo, __m128& cent_hi) {
  if (!indices_in_range(mesh, t)) return tri_bad_index;
  const uint32_t* idx = &mesh.indices[3 * t];
  const Vec3 a = mesh.positions[idx[0]], b = mesh.positions[idx[1]], c = mesh.positions[idx[2]];
  if (const uint8_t kind = classify_vertices(a, b, c); kind != tri_valid) return kind;
  const __m128 va = _mm_setr_ps(a.x, a.y, a.z, 0.0f), vb = _mm_setr_ps(b.x, b.y, b.z, 0.0f),
               vc = _mm_setr_ps(c.x, c.y, c.z, 0.0f);
  const __m128 lo = _mm_min_ps(vc, _mm_min_ps(vb, va)), hi = _mm_max_ps(vc, _mm_max_ps(vb, va));
  // lo's lane 3 carries the prim id, hi's the spare word (0).
  _mm_store_ps(&out.lo.x, _mm_or_ps(lo, _mm_castsi128_ps(_mm_setr_epi32(0, 0, 0, int32_t(gid)))));
  _mm_store_ps(&out.hi.x, hi);
  const __m128 centroid = _mm_add_ps(lo, hi);
  cent_lo = _mm_min_ps(centroid, cent_lo);
  cent_hi = _mm_max_ps(centroid, cent_hi);
  return tri_valid;
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
    __m128 cent_lo = _mm_set1_ps(std::numeric_limits<float>::infinity());
    __m128 cent_hi = _mm_set1_ps(-std::numeric_limits<float>::infinity());
    visit([&](size_t gid, const TriangleMesh& mesh, size_t t) {
      kind[gid] = classify_and_ref(mesh, t, uint32_t(gid), refs[gid], cent_lo, cent_hi);
    });
    alignas(16) float lo[4], hi[4];
    _mm_store_ps(lo, cent_lo);
    _mm_store_ps(hi, cent_hi);
    const Bounds3 local{{lo[0], lo[1], lo[2]}, {hi[0], hi[1], hi[2]}};
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
