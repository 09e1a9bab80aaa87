// Deterministic node placement for parallel top-down builders.
//
// A subtree over n primitives has at most 2n - 1 nodes, so each subtree can be given a fixed
// range of slots before its children are built, whatever thread builds them: a node whose
// children pair sits at slots [d, d+1] puts the left child's descendants from d + 2 and the
// right child's from d + 2 * left_count. The slot array has gaps (leaves holding several
// primitives use fewer nodes); compact_slots() closes them, keeping the depth-first order,
// from the subtree sizes the builder records (in parallel, with more than one thread). This
// is what makes a parallel build bit-identical to a serial one.
#pragma once
#include <cstdint>
#include <memory>
#include <span>

#include "core/parallel.h"
#include "core/raw_array.h"
#include "kestrel/bvh.h"

namespace kestrel {

/// Uninitialised storage for 2n slots (the nodes are written before being read), and the
/// node count of each inner node's subtree (set_subtree_nodes, read by compact_slots).
struct NodeSlots {
  explicit NodeSlots(size_t prim_count);
  Bvh2Node* data() { return slots_.data(); }
  Bvh2Node& operator[](size_t i) { return slots_[i]; }
  const Bvh2Node& operator[](size_t i) const { return slots_[i]; }
  /// Records inner node `slot`'s subtree (itself and its descendants) and returns its size.
  uint32_t set_subtree_nodes(uint32_t slot, uint32_t left_nodes, uint32_t right_nodes) {
    return sizes_[slot] = 1 + left_nodes + right_nodes;
  }
  uint32_t subtree_nodes(size_t slot) const { return slots_[slot].is_leaf() ? 1 : sizes_[slot]; }

 private:
  RawArray<Bvh2Node> slots_;
  RawArray<uint32_t> sizes_;
};

/// Descendant range start of the right child, given the pair at `pair` and left count.
inline uint32_t right_descendants(uint32_t pair, size_t left_count) {
  return pair + 2 * static_cast<uint32_t>(left_count);
}

/// Builds the two subtrees of a node: in parallel (through core/parallel.h) for large
/// ranges, else one after the other. Slots are fixed in advance, so both give the same tree.
inline void build_children(bool parallel, FunctionRef<void()> left, FunctionRef<void()> right) {
  if (parallel) {
    parallel_invoke(left, right);
  } else {
    left();
    right();
  }
}

/// Closes the gaps: the tree rooted at slot 0, with leaves indexing `ordered_prim_ids`,
/// becomes a compact Bvh2 (depth-first, children pairs adjacent: a node's descendants are
/// one run of the array, its children's pair first). Every inner node's subtree size must
/// have been recorded (set_subtree_nodes). The same array for any thread count.
Bvh2 compact_slots(const NodeSlots& slots, std::span<const uint32_t> ordered_prim_ids);

}  // namespace kestrel
