// Turning scene triangles into builder input (PrimRefs) and intersection input (Triangles).
#pragma once
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

}  // namespace kestrel
