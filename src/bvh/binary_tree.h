// A binary tree with one primitive per leaf, as the LBVH emits it and the treelet optimizer
// rewrites it; converted to the canonical Bvh2 by emit_bvh2(), which collapses subtrees into
// leaves wherever the SAH says a leaf is cheaper (Karras & Aila 2013, section 4.3).
#pragma once
#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

#include "core/raw_array.h"
#include "core/simd/vec4f.h"
#include "core/vec.h"

#include "kestrel/bvh.h"

namespace kestrel {

struct BinaryTree {
  /// A child reference: an inner node id, or a leaf id with `leaf_bit` set.
  static constexpr uint32_t leaf_bit = 0x80000000u;
  static constexpr uint32_t no_parent = 0xFFFFFFFFu;

  RawArray<PrimRef> leaves;        ///< leaf i holds primitive leaves[i]
  RawArray<uint32_t> left, right;  ///< per inner node (n - 1 of them)
  RawArray<uint32_t> parent;       ///< per inner node; no_parent for the root
  RawArray<uint32_t> leaf_parent;  ///< per leaf; no_parent when the leaf is the root
  /// Inner node box, laid out like PrimRef (lo in bytes 0-11, hi in 16-27) so a child's
  /// corners load as two aligned 16-byte vectors whether it is a leaf or an inner node.
  struct alignas(16) Box {
    float lo[4], hi[4];
  };
  RawArray<Box> bounds;      ///< per inner node
  RawArray<uint32_t> count;  ///< primitives below each inner node | collapse_bit
  static constexpr uint32_t collapse_bit =
      0x80000000u;       ///< set: one leaf is cheaper than the subtree
  RawArray<float> cost;  ///< SAH cost (absolute: area x cost) of each inner node
  uint32_t root = 0;     ///< child reference of the root

  size_t inner_count() const { return left.size(); }
  /// Sizes every array for n leaves (contents uninitialised).
  void allocate(size_t n);
  static bool is_leaf(uint32_t ref) { return ref & leaf_bit; }
  static uint32_t leaf_index(uint32_t ref) { return ref & ~leaf_bit; }
};

// Corners, bounds, area, cost and primitive count of a child reference (inline: the
// bottom-up passes call them once per node).
inline const float* child_corners(const BinaryTree& tree, uint32_t ref) {
  static_assert(offsetof(PrimRef, hi) == offsetof(BinaryTree::Box, hi));
  return BinaryTree::is_leaf(ref) ? &tree.leaves[BinaryTree::leaf_index(ref)].lo.x
                                  : tree.bounds[ref].lo;
}
inline Bounds3 child_bounds(const BinaryTree& tree, uint32_t ref) {
  const float* c = child_corners(tree, ref);
  return {{c[0], c[1], c[2]}, {c[4], c[5], c[6]}};
}
inline float child_area(const BinaryTree& tree, uint32_t ref) {
  const float* c = child_corners(tree, ref);
  return simd::half_area(simd::Vec4f::load(c), simd::Vec4f::load(c + 4));
}
inline float child_cost(const BinaryTree& tree, uint32_t ref, const BuildConfig& config) {
  if (BinaryTree::is_leaf(ref)) return config.intersection_cost * child_area(tree, ref);
  return tree.cost[ref];
}
inline uint32_t child_count(const BinaryTree& tree, uint32_t ref) {
  return BinaryTree::is_leaf(ref) ? 1u : tree.count[ref] & ~BinaryTree::collapse_bit;
}
/// Whether the SAH prefers the inner node's subtree as a single leaf (set by refit_node).
inline bool prefers_leaf(const BinaryTree& tree, uint32_t node) {
  return tree.count[node] & BinaryTree::collapse_bit;
}

/// Recomputes an inner node's bounds, count and cost (and its collapse decision) from its
/// children.
inline void refit_node(BinaryTree& tree, uint32_t node, const BuildConfig& config) {
  using simd::Vec4f;
  const uint32_t l = tree.left[node], r = tree.right[node];
  const float* cl = child_corners(tree, l);
  const float* cr = child_corners(tree, r);
  const Vec4f llo = Vec4f::load(cl), lhi = Vec4f::load(cl + 4), rlo = Vec4f::load(cr),
              rhi = Vec4f::load(cr + 4);
  const Vec4f lo = min(llo, rlo), hi = max(lhi, rhi);
  const uint32_t n = child_count(tree, l) + child_count(tree, r);
  const float area = simd::half_area(lo, hi);
  const float cost_l =
      BinaryTree::is_leaf(l) ? config.intersection_cost * simd::half_area(llo, lhi) : tree.cost[l];
  const float cost_r =
      BinaryTree::is_leaf(r) ? config.intersection_cost * simd::half_area(rlo, rhi) : tree.cost[r];
  const float split = config.traversal_cost * area + cost_l + cost_r;
  const float leaf = config.intersection_cost * area * float(n);
  const bool collapse = n <= config.max_leaf_size && leaf <= split;
  lo.store(tree.bounds[node].lo);
  hi.store(tree.bounds[node].hi);
  tree.count[node] = n | (collapse ? BinaryTree::collapse_bit : 0u);
  tree.cost[node] = collapse ? leaf : split;
}

/// Bottom-up pass in parallel (a node is handled by whichever of its children's walks
/// arrives second): refits every inner node and then calls visit(node) on it.
/// visit may rewrite the subtree below the node (it is complete by then).
void bottom_up(BinaryTree& tree, const BuildConfig& config,
               void (*visit)(BinaryTree&, uint32_t, const BuildConfig&, void*), void* user);

/// Converts to Bvh2, collapsing subtrees of at most max_leaf_size primitives into one leaf
/// where that is cheaper by the SAH, and every subtree of at most `block_leaf` primitives
/// (0: none; 4 for a tree that becomes 4-triangle blocks, see build_bvh_for_blocks).
Bvh2 emit_bvh2(const BinaryTree& tree, const BuildConfig& config, uint32_t block_leaf = 0);

}  // namespace kestrel

namespace kestrel {
/// The LBVH's one-primitive-per-leaf tree with bounds and costs (lbvh_builder.cpp).
BinaryTree build_lbvh_tree(std::span<const PrimRef> refs, const BuildConfig& config);
/// The same tree emitted top-down by Karras' binary searches: the tests' oracle for the
/// bottom-up emission (both give the same topology by construction).
BinaryTree build_lbvh_tree_karras(std::span<const PrimRef> refs, const BuildConfig& config);
}  // namespace kestrel
