// A binary tree with one primitive per leaf, as the LBVH emits it and the treelet optimizer
// rewrites it; converted to the canonical Bvh2 by emit_bvh2(), which collapses subtrees into
// leaves wherever the SAH says a leaf is cheaper (Karras & Aila 2013, section 4.3).
#pragma once
#include <cstdint>
#include <span>
#include <vector>

#include "kestrel/bvh.h"

namespace kestrel {

struct BinaryTree {
  /// A child reference: an inner node id, or a leaf id with `leaf_bit` set.
  static constexpr uint32_t leaf_bit = 0x80000000u;
  static constexpr uint32_t no_parent = 0xFFFFFFFFu;

  std::vector<PrimRef> leaves;        ///< leaf i holds primitive leaves[i]
  std::vector<uint32_t> left, right;  ///< per inner node (n - 1 of them; root = 0)
  std::vector<uint32_t> parent;       ///< per inner node; no_parent for the root
  std::vector<uint32_t> leaf_parent;  ///< per leaf
  std::vector<Bounds3> bounds;        ///< per inner node
  std::vector<uint32_t> count;        ///< primitives below each inner node
  std::vector<float> cost;            ///< SAH cost (absolute: area x cost) of each inner node

  size_t inner_count() const { return left.size(); }
  static bool is_leaf(uint32_t ref) { return ref & leaf_bit; }
  static uint32_t leaf_index(uint32_t ref) { return ref & ~leaf_bit; }
};

/// Half area and cost of a child reference.
float child_area(const BinaryTree& tree, uint32_t ref);
float child_cost(const BinaryTree& tree, uint32_t ref, const BuildConfig& config);
Bounds3 child_bounds(const BinaryTree& tree, uint32_t ref);
uint32_t child_count(const BinaryTree& tree, uint32_t ref);

/// Recomputes an inner node's bounds, count and cost from its children.
void refit_node(BinaryTree& tree, uint32_t node, const BuildConfig& config);

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
}  // namespace kestrel
