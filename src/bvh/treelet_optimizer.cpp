// Treelet restructuring (Karras & Aila 2013, "Fast parallel construction of high-quality
// bounding volume hierarchies"). NOTE: covered by NVIDIA patents (US 10331632 and related);
// offered as the opt-in `treelet` builder only, never chosen by a BuildQuality.
//
// Bottom-up over the LBVH tree (in parallel: each node is handled once both its subtrees
// are final), a treelet of up to 7 leaves is grown below each node by repeatedly opening the
// treelet leaf with the largest surface area. Dynamic programming over all leaf subsets
// finds the treelet topology of least SAH cost (including collapsing a subset into one
// leaf); if it beats the current one, the treelet's inner nodes are rewired in place.
// Several rounds are run. The work below a node depends only on that subtree, so the result
// is the same for any thread count.
#include <algorithm>
#include <bit>
#include <limits>

#include "bvh/binary_tree.h"
#include "bvh/builders.h"
#include "core/vec.h"

namespace kestrel {

namespace {

constexpr int max_treelet_leaves = 7;
constexpr int max_subsets = 1 << max_treelet_leaves;

struct TreeletParams {
  uint32_t leaf_target;  // leaves per treelet
  uint32_t min_prims;    // only nodes with at least this many primitives are roots
};

void restructure_node(BinaryTree& tree, uint32_t root, const BuildConfig& config, void* user) {
  const TreeletParams& params = *static_cast<const TreeletParams*>(user);
  if (child_count(tree, root) < params.min_prims) return;

  // Grow the treelet: open the largest-area inner leaf until there are leaf_target leaves.
  uint32_t leaves[max_treelet_leaves];
  float leaf_area[max_treelet_leaves];
  uint32_t inner[max_treelet_leaves];  // treelet inner nodes other than the root
  int leaf_count = 2, inner_count = 0;
  leaves[0] = tree.left[root];
  leaves[1] = tree.right[root];
  leaf_area[0] = child_area(tree, leaves[0]);
  leaf_area[1] = child_area(tree, leaves[1]);
  while (leaf_count < int(params.leaf_target)) {
    int best = -1;
    for (int i = 0; i < leaf_count; ++i)
      if (!BinaryTree::is_leaf(leaves[i]) && (best < 0 || leaf_area[i] > leaf_area[best])) best = i;
    if (best < 0) break;
    const uint32_t opened = leaves[best];
    inner[inner_count++] = opened;
    leaves[best] = tree.left[opened];
    leaf_area[best] = child_area(tree, leaves[best]);
    leaves[leaf_count] = tree.right[opened];
    leaf_area[leaf_count] = child_area(tree, leaves[leaf_count]);
    ++leaf_count;
  }
  if (leaf_count < 3) return;

  // Optimal topology over subsets of the treelet's leaves.
  const int full = (1 << leaf_count) - 1;
  Bounds3 sub_bounds[max_subsets];
  float area[max_subsets], best_cost[max_subsets];
  uint32_t prims[max_subsets];
  uint8_t best_part[max_subsets];
  for (int s = 1; s <= full; ++s) {
    const int low = s & -s;
    if (s == low) {
      const int i = std::countr_zero(unsigned(s));
      sub_bounds[s] = child_bounds(tree, leaves[i]);
      prims[s] = child_count(tree, leaves[i]);
      area[s] = half_area(sub_bounds[s]);
      best_cost[s] = child_cost(tree, leaves[i], config);
      continue;
    }
    sub_bounds[s] = merge(sub_bounds[s ^ low], sub_bounds[low]);
    prims[s] = prims[s ^ low] + prims[low];
    area[s] = half_area(sub_bounds[s]);
    // Each unordered partition once: the part holding the lowest bit.
    float best = std::numeric_limits<float>::infinity();
    int part = 0;
    for (int p = (s - 1) & s; p > 0; p = (p - 1) & s) {
      if (!(p & low)) continue;
      const float c = best_cost[p] + best_cost[s ^ p];
      if (c < best) {
        best = c;
        part = p;
      }
    }
    float c = config.traversal_cost * area[s] + best;
    if (prims[s] <= config.max_leaf_size)
      c = std::min(c, config.intersection_cost * area[s] * float(prims[s]));
    best_cost[s] = c;
    best_part[s] = uint8_t(part);
  }
  if (!(best_cost[full] < tree.cost[root] * (1.0f - 1e-6f))) return;

  // Rewire: the root keeps its id, the other inner ids are reused in order.
  int next_inner = 0;
  auto assign = [&](auto&& self, int s, uint32_t node) -> void {
    const int parts[2] = {best_part[s], s ^ best_part[s]};
    uint32_t children[2];
    for (int k = 0; k < 2; ++k) {
      if (std::has_single_bit(unsigned(parts[k]))) {
        children[k] = leaves[std::countr_zero(unsigned(parts[k]))];
      } else {
        children[k] = inner[next_inner++];
        self(self, parts[k], children[k]);
      }
      if (BinaryTree::is_leaf(children[k]))
        tree.leaf_parent[BinaryTree::leaf_index(children[k])] = node;
      else
        tree.parent[children[k]] = node;
    }
    tree.left[node] = children[0];
    tree.right[node] = children[1];
    refit_node(tree, node, config);
  };
  assign(assign, full, root);
}

}  // namespace

void restructure_treelets(BinaryTree& tree, const BuildConfig& config) {
  TreeletParams params{config.treelet_leaf_count, config.treelet_leaf_count};
  for (uint32_t round = 0; round < config.treelet_rounds; ++round)
    bottom_up(tree, config, &restructure_node, &params);
}

/// Runs config.treelet_rounds rounds of restructuring over the tree, in place.
void restructure_treelets(BinaryTree& tree, const BuildConfig& config);

Bvh2 build_treelet(std::span<const PrimRef> refs, const BuildConfig& config) {
  BinaryTree tree = build_lbvh_tree(refs, config);
  restructure_treelets(tree, config);
  return emit_bvh2(tree, config);
}

}  // namespace kestrel
