// The builders (one file each) behind build_bvh(). Each is a function of the references and
// the config returning the canonical Bvh2; none sees triangles.
#pragma once
#include <span>

#include "kestrel/bvh.h"

namespace kestrel {

Bvh2 build_median(std::span<const PrimRef> refs, const BuildConfig& config);
Bvh2 build_sweep_sah(std::span<const PrimRef> refs, const BuildConfig& config);
/// block_leaves: the tree becomes a wide BVH with 4-triangle blocks (collapse_to_bvh4/8), which
/// makes every subtree of at most 4 primitives one block whatever its shape, so ranges that
/// small become leaves at once instead of being split further.
Bvh2 build_binned_sah(std::span<const PrimRef> refs, const BuildConfig& config,
                      bool block_leaves = false);
/// block_leaves: as build_binned_sah's (subtrees of at most 4 primitives emitted as leaves).
Bvh2 build_lbvh(std::span<const PrimRef> refs, const BuildConfig& config,
                bool block_leaves = false);
/// Binned SAH with spatial splits (Stich et al. 2009). triangles[prim_id] are clipped at the
/// split planes; empty: the reference boxes are cut instead. block_leaves: as
/// build_binned_sah's.
Bvh2 build_spatial_sah(std::span<const PrimRef> refs, std::span<const Triangle> triangles,
                       const BuildConfig& config, bool block_leaves = false);
/// LBVH followed by treelet restructuring (Karras & Aila 2013; US patent 10331632).
Bvh2 build_treelet(std::span<const PrimRef> refs, const BuildConfig& config);

/// build_bvh for a tree that becomes a wide BVH of 4-triangle blocks (build_accel with a
/// bvh4 or bvh8 layout): the same wide tree, built with less work below 4 primitives.
Bvh2 build_bvh_for_blocks(std::span<const PrimRef> refs, std::span<const Triangle> triangles,
                          const BuildConfig& config);

}  // namespace kestrel
