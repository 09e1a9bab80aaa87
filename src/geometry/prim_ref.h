// Turning scene triangles into builder input (PrimRefs) and intersection input (Triangles).
#pragma once
#include <vector>

#include "kestrel/bvh.h"
#include "kestrel/trace.h"

namespace kestrel {

/// One PrimRef per valid triangle (prim_id = global triangle id, in scene order), in
/// parallel. Invalid triangles (see validate_scene) are skipped.
std::vector<PrimRef> make_prim_refs(const Scene& scene, const SceneValidation& validation);

/// All triangles of the scene by global id (invalid ones are zero triangles: never hit).
std::vector<Triangle> gather_triangles(const Scene& scene, const SceneValidation& validation);

}  // namespace kestrel
