#include "bvh/binary_tree.h"

#include <algorithm>
#include <atomic>
#include <memory>

#include "core/parallel.h"
#include "core/vec.h"

namespace kestrel {

void BinaryTree::allocate(size_t n) {
  leaves.resize(n);
  leaf_parent.resize(n);
  const size_t inner = n ? n - 1 : 0;
  left.resize(inner);
  right.resize(inner);
  parent.resize(inner);
  bounds.resize(inner);
  count.resize(inner);
  cost.resize(inner);
}

void bottom_up(BinaryTree& tree, const BuildConfig& config,
               void (*visit)(BinaryTree&, uint32_t, const BuildConfig&, void*), void* user) {
  const size_t inner = tree.inner_count();
  if (inner == 0) return;
  std::unique_ptr<std::atomic<uint32_t>[]> arrivals(new std::atomic<uint32_t>[inner]);
  for (size_t i = 0; i < inner; ++i) arrivals[i].store(0, std::memory_order_relaxed);
  parallel_for(0, tree.leaves.size(), 4096, [&](size_t b, size_t e) {
    for (size_t leaf = b; leaf < e; ++leaf) {
      uint32_t node = tree.leaf_parent[leaf];
      while (node != BinaryTree::no_parent) {
        // The first child to arrive stops; the second sees the first's writes (acq_rel).
        if (arrivals[node].fetch_add(1, std::memory_order_acq_rel) == 0) break;
        refit_node(tree, node, config);
        if (visit) visit(tree, node, config, user);
        node = tree.parent[node];
      }
    }
  });
}

namespace {
void gather_leaves(const BinaryTree& tree, uint32_t ref, std::vector<uint32_t>& out) {
  // Collapsed subtrees hold at most max_leaf_size (<= 255) primitives.
  uint32_t stack[512];  // a subtree of k leaves never needs more than k + 1 entries
  int top = 0;
  stack[top++] = ref;
  while (top) {
    uint32_t r = stack[--top];
    if (BinaryTree::is_leaf(r)) {
      out.push_back(tree.leaves[BinaryTree::leaf_index(r)].prim_id);
    } else {
      stack[top++] = tree.right[r];
      stack[top++] = tree.left[r];
    }
  }
}
}  // namespace

Bvh2 emit_bvh2(const BinaryTree& tree, const BuildConfig& config, uint32_t block_leaf) {
  Bvh2 out;
  const size_t n = tree.leaves.size();
  if (n == 0) return out;
  out.prim_ids.reserve(n);
  out.nodes.resize(2 * n - 1);
  // (tree reference, output node) pairs, depth first. Depth is bounded by the tree's
  // height; the stack grows only if a tree is unusually deep.
  std::vector<std::pair<uint32_t, uint32_t>> stack;
  stack.reserve(256);
  stack.push_back({tree.root, 0});
  uint32_t next = 1;
  while (!stack.empty()) {
    auto [ref, o] = stack.back();
    stack.pop_back();
    const Bounds3 b = child_bounds(tree, ref);
    if (BinaryTree::is_leaf(ref) || prefers_leaf(tree, ref) ||
        child_count(tree, ref) <= block_leaf) {
      const uint32_t first = uint32_t(out.prim_ids.size());
      gather_leaves(tree, ref, out.prim_ids);
      out.nodes[o] = Bvh2Node{b.lo, first, b.hi, uint32_t(out.prim_ids.size() - first)};
    } else {
      const uint32_t pair = next;
      next += 2;
      out.nodes[o] = Bvh2Node{b.lo, pair, b.hi, 0};
      stack.push_back({tree.right[ref], pair + 1});
      stack.push_back({tree.left[ref], pair});
    }
  }
  out.nodes.resize(next);
  return out;
}

}  // namespace kestrel
