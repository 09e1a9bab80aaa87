// Turning scene triangles into builder input (PrimRefs) and intersection input (Triangles).
#pragma once
#include <algorithm>
#include <span>
#include <vector>

#include "kestrel/bvh.h"
#include "kestrel/trace.h"

namespace kestrel {

/// One PrimRef per valid triangle (prim_id = global triangle id, in scene order), in
/// parallel. Invalid triangles (see validate_scene) are skipped.
Buffer<PrimRef> make_prim_refs(const Scene& scene, const SceneValidation& validation);

/// Validation and PrimRefs in one pass over the vertices (each triangle's vertices are read
/// once): what build_accel uses. `centroids`, when given: the bounds of the valid refs'
/// doubled centroids (lo + hi, as centroid_bounds), from the same pass.
Buffer<PrimRef> validate_and_make_prim_refs(const Scene& scene, SceneValidation& validation,
                                            Bounds3* centroids = nullptr);

/// All triangles of the scene by global id (invalid ones are zero triangles: never hit).
Buffer<Triangle> gather_triangles(const Scene& scene, const SceneValidation& validation);

/// What a builder needs besides the references: for `spatial`, every triangle by global id
/// (it clips them at its split planes); nothing for the other builders.
Buffer<Triangle> triangles_for_builder(const Scene& scene, const SceneValidation& validation,
                                       Builder builder);

/// The triangles of the given global prim ids, in that order (e.g. a BVH's leaf order).
Buffer<Triangle> gather_triangles(const Scene& scene, std::span<const uint32_t> prim_ids);

/// Where each mesh's triangles start among the scene's global prim ids (mesh m holds
/// [start(m), start(m + 1))), and the mesh of a global id.
class MeshStarts {
 public:
  explicit MeshStarts(const Scene& scene) : first_{0} {
    for (const TriangleMesh& mesh : scene.meshes)
      first_.push_back(first_.back() + mesh.triangle_count());
  }
  size_t start(size_t m) const { return first_[m]; }
  size_t total() const { return first_.back(); }
  /// The mesh holding global id `gid` < total() (empty meshes, which hold none, skipped).
  size_t mesh_of(size_t gid) const {
    return size_t(std::upper_bound(first_.begin(), first_.end(), gid) - first_.begin()) - 1;
  }

 private:
  std::vector<size_t> first_;  // first global id of each mesh, then the total
};

/// The triangles of global prim ids read straight from the meshes: at(k) is the triangle of
/// ids[k]. Read in ascending k, it prefetches in two stages -- the index triple 2 x `ahead`
/// positions on, the vertices of the triangle `ahead` on -- since scrambled meshes make the
/// vertex reads miss the caches (gather_triangles and the direct wide LBVH's blocks).
class TrianglesById {
 public:
  static constexpr size_t ahead = 16;
  TrianglesById(const Scene& scene, std::span<const uint32_t> ids)
      : scene_(scene), ids_(ids), starts_(scene) {}
  Triangle at(size_t k) const {
    if (k + 2 * ahead < ids_.size()) {
      const auto [mesh, t] = locate(ids_[k + 2 * ahead]);
      __builtin_prefetch(&mesh->indices[3 * t]);
    }
    if (k + ahead < ids_.size()) {
      const auto [mesh, t] = locate(ids_[k + ahead]);
      const uint32_t* idx = &mesh->indices[3 * t];
      for (int c = 0; c < 3; ++c) __builtin_prefetch(&mesh->positions[idx[c]]);
    }
    const auto [mesh, t] = locate(ids_[k]);
    const uint32_t* idx = &mesh->indices[3 * t];
    return {mesh->positions[idx[0]], mesh->positions[idx[1]], mesh->positions[idx[2]]};
  }

 private:
  // (mesh, local triangle) of a global id.
  std::pair<const TriangleMesh*, size_t> locate(uint32_t gid) const {
    if (scene_.meshes.size() == 1) return {&scene_.meshes[0], gid};
    const size_t m = starts_.mesh_of(gid);
    return {&scene_.meshes[m], gid - starts_.start(m)};
  }
  const Scene& scene_;
  std::span<const uint32_t> ids_;
  MeshStarts starts_;
};

}  // namespace kestrel
