// A binary tree with one primitive per leaf, as the LBVH emits it and the treelet optimizer
// rewrites it; converted to the canonical Bvh2 by emit_bvh2(), which collapses subtrees into
// leaves wherever the SAH says a leaf is cheaper (Karras & Aila 2013, section 4.3).
#pragma once
#include <algorithm>
#include <cstdint>
#include <span>
#include <vector>

#include "core/raw_array.h"
#include "core/vec.h"

#include "kestrel/bvh.h"

namespace kestrel {

struct BinaryTree {
  /// A child reference: an inner node id, or a leaf id with `leaf_bit` set.
  static constexpr uint32_t leaf_bit = 0x80000000u;
  static constexpr uint32_t no_parent = 0xFFFFFFFFu;

  RawArray<PrimRef> leaves;         ///< leaf i holds primitive leaves[i]
  RawArray<uint32_t> left, right;   ///< per inner node (n - 1 of them)
  RawArray<uint32_t> parent;        ///< per inner node; no_parent for the root
  RawArray<uint32_t> leaf_parent;   ///< per leaf; no_parent when the leaf is the root
  RawArray<Bounds3> bounds;         ///< per inner node
  RawArray<uint32_t> count;         ///< primitives below each inner node | collapse_bit
  static constexpr uint32_t collapse_bit = 0x80000000u;  ///< set: one leaf is cheaper than the subtree
  RawArray<float> cost;             ///< SAH cost (absolute: area x cost) of each inner node
  uint32_t root = 0;                ///< child reference of the root

  size_t inner_count() const { return left.size(); }
  /// Sizes every array for n leaves (contents uninitialised).
  void allocate(size_t n);
  static bool is_leaf(uint32_t ref) { return ref & leaf_bit; }
  static uint32_t leaf_index(uint32_t ref) { return ref & ~leaf_bit; }
};

// Bounds, area, cost and primitive count of a child reference (inline: the bottom-up
// passes call them once per node).
inline Bounds3 child_bounds(const BinaryTree& tree, uint32_t ref) {
  if (BinaryTree::is_leaf(ref)) {
    const PrimRef& p = tree.leaves[BinaryTree::leaf_index(ref)];
    return {p.lo, p.hi};
  }
  return tree.bounds[ref];
}
inline float child_area(const BinaryTree& tree, uint32_t ref) { return half_area(child_bounds(tree, ref)); }
inline float child_cost(const BinaryTree& tree, uint32_t ref, const BuildConfig& config) {
  if (BinaryTree::is_leaf(ref)) return config.intersection_cost * child_area(tree, ref);
  return tree.cost[ref];
}
inline uint32_t child_count(const BinaryTree& tree, uint32_t ref) {
  return BinaryTree::is_leaf(ref) ? 1u : tree.count[ref] & ~BinaryTree::collapse_bit;
}
/// Whether the SAH prefers the inner node's subtree as a single leaf (set by refit_node).
inline bool prefers_leaf(const BinaryTree& tree, uint32_t node) { return tree.count[node] & BinaryTree::collapse_bit; }

/// Recomputes an inner node's bounds, count and cost from its children.
inline void refit_node(BinaryTree& tree, uint32_t node, const BuildConfig& config) {
  const uint32_t l = tree.left[node], r = tree.right[node];
  const Bounds3 b = merge(child_bounds(tree, l), child_bounds(tree, r));
  const uint32_t n = child_count(tree, l) + child_count(tree, r);
  const float area = half_area(b);
  const float split = config.traversal_cost * area + child_cost(tree, l, config) + child_cost(tree, r, config);
  const float leaf = config.intersection_cost * area * float(n);
  const bool collapse = n <= config.max_leaf_size && leaf <= split;
  tree.bounds[node] = b;
  tree.count[node] = n | (collapse ? BinaryTree::collapse_bit : 0u);
  tree.cost[node] = collapse ? leaf : split;
}

/// Bottom-up pass in parallel (a node is handled by whichever of its children's walks
/// arrives second): refits every inner node and then calls visit(node) on it.
/// visit may rewrite the subtree below the node (it is complete by then).
void bottom_up(BinaryTree& tree, const BuildConfig& config, void (*visit)(BinaryTree&, uint32_t, const BuildConfig&, void*),
               void* user);

/// Converts to Bvh2, collapsing subtrees of at most max_leaf_size primitives into one leaf
/// where that is cheaper by the SAH.
Bvh2 emit_bvh2(const BinaryTree& tree, const BuildConfig& config);

}  // namespace kestrel

namespace kestrel {
/// The LBVH's one-primitive-per-leaf tree with bounds and costs (lbvh_builder.cpp).
BinaryTree build_lbvh_tree(std::span<const PrimRef> refs, const BuildConfig& config);
/// The same tree emitted top-down by Karras' binary searches: the tests' oracle for the
/// bottom-up emission (both give the same topology by construction).
BinaryTree build_lbvh_tree_karras(std::span<const PrimRef> refs, const BuildConfig& config);
}  // namespace kestrel
