// Bvh2 -> Bvh4 / Bvh8 collapse and refit of the wide layouts.
#pragma once
#include <span>

#include "core/parallel.h"

#include "kestrel/trace.h"
#include "traverse/accel_nodes.h"

namespace kestrel {

/// Collapses a Bvh2 into a 4- or 8-wide BVH. leaf_triangles[i] is primitive bvh.prim_ids[i].
/// Each wide node starts from a binary node's two children and repeatedly opens the inner
/// child of largest surface area (the one a ray is most likely to visit, so the one whose
/// box test is most worth merging into the parent's SIMD test) until W children or only
/// leaves remain. Leaves are runs of TriangleBlocks; binary subtrees of at most
/// max(max_leaf, 4) primitives become one leaf where a block-counting SAH prefers it.
Bvh4 collapse_to_bvh4(const Bvh2& bvh, std::span<const Triangle> leaf_triangles, uint32_t max_leaf);
Bvh8 collapse_to_bvh8(const Bvh2& bvh, std::span<const Triangle> leaf_triangles, uint32_t max_leaf);
/// The same, reading each leaf triangle from its mesh (bvh.prim_ids are global triangle ids of
/// `scene`): no gathered copy of the triangles.
Bvh4 collapse_to_bvh4(const Bvh2& bvh, const Scene& scene, uint32_t max_leaf);
Bvh8 collapse_to_bvh8(const Bvh2& bvh, const Scene& scene, uint32_t max_leaf);

/// Writes child slot j of a wide node: its box into the six bound rows, and its reference.
template <class Node>
inline void set_wide_slot(Node& node, int j, const Bounds3& b, uint32_t ref) {
  node.bounds[0][j] = b.lo.x, node.bounds[1][j] = b.hi.x;
  node.bounds[2][j] = b.lo.y, node.bounds[3][j] = b.hi.y;
  node.bounds[4][j] = b.lo.z, node.bounds[5][j] = b.hi.z;
  node.child[j] = ref;
}

/// Writes a triangle's vertices and prim id into one lane of a block.
inline void write_block_lane(TriangleBlock& block, int lane, const Triangle& t, uint32_t id) {
  const Vec3* v[3] = {&t.v0, &t.v1, &t.v2};
  for (int k = 0; k < 3; ++k) {
    block.v[k][0][lane] = v[k]->x;
    block.v[k][1][lane] = v[k]->y;
    block.v[k][2][lane] = v[k]->z;
  }
  block.prim_id[lane] = id;
}
/// Writes new vertices into a run of leaf blocks (a contiguous part of bvh.blocks; runs are
/// disjoint and may be rewritten in parallel). Returns the smallest prim id whose triangle can
/// no longer be traced (NaN/Inf vertex, bad index), or ~0u.
using BlockRewrite = FunctionRef<uint32_t(std::span<TriangleBlock>)>;
/// Refit in two passes: every block rewritten and boxed in memory order (prefetch-friendly,
/// chunks in parallel), then every node box bottom-up (children follow their parent in the
/// node array) from its children's boxes. Throws naming the triangle if rewrite reports one.
/// Returns the refitted tree's SAH cost: wide_sah_cost(bvh) afterwards, summed in another order.
double refit_wide(Bvh4& bvh, BlockRewrite rewrite);
double refit_wide(Bvh8& bvh, BlockRewrite rewrite);

/// A wide tree over instances: bvh's leaves hold one primitive each (max_leaf_size = 1), and
/// become child references wide_leaf_bit | prim_id.
Buffer<Bvh4Node> collapse_instances_bvh4(const Bvh2& bvh);
Buffer<Bvh8Node> collapse_instances_bvh8(const Bvh2& bvh);

/// Bounds of everything in a wide BVH (the union of the root's child boxes).
Bounds3 wide_bounds(const Bvh4& bvh);
Bounds3 wide_bounds(const Bvh8& bvh);

/// SAH cost of a wide BVH: 1 (the root) + sum over child slots of area x (1 for an inner
/// child, blocks for a leaf), over the root's area. Compares a refitted tree with itself
/// after its last full build.
double wide_sah_cost(const Bvh4& bvh);
double wide_sah_cost(const Bvh8& bvh);

/// refit_accel that also returns the refitted tree's SAH cost (wide_sah_cost; 0 for bvh2).
double refit_accel_cost(Accel& accel, const Scene& scene);

/// Recomputes a Bvh2's boxes from triangles in leaf order.
void refit_bvh2(Bvh2& bvh, std::span<const Triangle> leaf_triangles);

}  // namespace kestrel
