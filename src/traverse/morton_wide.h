// The LBVH made ready to trace in one go: Morton order straight to wide nodes and triangle
// blocks, with no binary tree in between.
#pragma once
#include <span>

#include "kestrel/bvh.h"
#include "kestrel/scene.h"
#include "traverse/accel_nodes.h"

namespace kestrel {

/// A 4- or 8-wide BVH over `refs` (valid triangles of `scene`, as validate_and_make_prim_refs
/// makes them). The refs are sorted by the Morton code of their centroids (config.morton_bits:
/// 30 or 63) and each node splits its sorted range where the highest differing code bit flips
/// (Karras 2012), splitting a part again -- the one of the largest Morton cell, then of most
/// references -- until it has W parts; a range of at most
/// four triangles is a leaf of one TriangleBlock (config.max_leaf_size does not apply). Boxes
/// come from the blocks' own vertices, bottom-up. Ranges of at most 4 096 triangles are
/// parallel tasks: each is counted first, given its place after the top nodes in task order
/// and built there, so the result does not depend on the thread count.
/// `centroids`: the refs' centroid bounds when known (validate_and_make_prim_refs), else
/// computed.
Bvh4 build_morton_bvh4(const Scene& scene, std::span<const PrimRef> refs, const BuildConfig& config,
                       const Bounds3* centroids = nullptr);
Bvh8 build_morton_bvh8(const Scene& scene, std::span<const PrimRef> refs, const BuildConfig& config,
                       const Bounds3* centroids = nullptr);

}  // namespace kestrel
