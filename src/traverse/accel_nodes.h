// What an Accel holds (internal): the binary tree and its triangles (layout bvh2) or the wide
// nodes and triangle blocks (bvh4 / bvh8), with their byte layouts (docs/bvh_layout.md).
#pragma once
#include <cstdint>
#include <memory>

#include "kestrel/bvh.h"
#include "kestrel/trace.h"

namespace kestrel {

/// Wide-node child reference: an inner node's index, or wide_leaf_bit | the first
/// TriangleBlock of a leaf (its blocks run to the one whose prim_id[0] has block_last_bit),
/// or wide_empty for an unused slot (whose box is empty: lo = +inf, hi = -inf).
inline constexpr uint32_t wide_leaf_bit = 0x80000000u;
inline constexpr uint32_t wide_empty = 0xFFFFFFFFu;
inline constexpr uint32_t block_last_bit = 0x80000000u;

/// 4-wide node, structure of arrays, 112 bytes: bounds[0..5] = lo.x, hi.x, lo.y, hi.y,
/// lo.z, hi.z of the four children (one 128-bit row each), then the child references.
struct alignas(16) Bvh4Node {
  float bounds[6][4];
  uint32_t child[4];
};
static_assert(sizeof(Bvh4Node) == 112);

/// 8-wide node, structure of arrays, 224 bytes: six 256-bit rows of child bounds (as in
/// Bvh4Node) and eight child references.
struct alignas(32) Bvh8Node {
  float bounds[6][8];
  uint32_t child[8];
};
static_assert(sizeof(Bvh8Node) == 224);

/// Four triangles for one SIMD leaf test, 160 bytes: v[vertex][axis][lane] then the global
/// prim ids (prim_id[0] also carries block_last_bit). A leaf of k triangles has ceil(k/4)
/// blocks; unused lanes repeat the leaf's last triangle (same id, so never a different hit).
struct alignas(16) TriangleBlock {
  float v[3][3][4];
  uint32_t prim_id[4];
};
static_assert(sizeof(TriangleBlock) == 160);

/// Wide BVHs: nodes[0] is the root (always an inner node); leaves are runs of blocks.
struct Bvh4 {
  Buffer<Bvh4Node> nodes;
  Buffer<TriangleBlock> blocks;
  bool empty() const { return nodes.empty(); }
};
struct Bvh8 {
  Buffer<Bvh8Node> nodes;
  Buffer<TriangleBlock> blocks;
  bool empty() const { return nodes.empty(); }
};

namespace detail {
struct PacketChoices;  // traverse/stream.h
struct AccelNodes {
  Bvh2 bvh;                    ///< bvh2 layout
  Buffer<Triangle> triangles;  ///< bvh2: triangles[i] is primitive bvh.prim_ids[i]
  Bvh4 bvh4;                   ///< bvh4 layout (the binary tree is released)
  Bvh8 bvh8;                   ///< bvh8 layout
  /// Coherent batches as packets or single rays, timed as they run (trace.cpp).
  std::unique_ptr<PacketChoices> choices;
  AccelNodes();
  ~AccelNodes();
};
}  // namespace detail

/// Reference: every valid triangle against the ray (the tests' oracle).
Hit intersect_brute_force(std::span<const Triangle> triangles, std::span<const uint8_t> valid,
                          const Ray& ray, bool any_hit);

}  // namespace kestrel
