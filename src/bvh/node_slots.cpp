#include "bvh/node_slots.h"

#include <cstdlib>
#include <new>
#include <vector>

namespace kestrel {

NodeSlots::NodeSlots(size_t prim_count) : slots_(2 * prim_count + 2), sizes_(2 * prim_count + 2) {}

namespace {

// Subtrees of fewer nodes are compacted by one task.
constexpr uint32_t compact_grain = 8192;

// Copies the subtree at slot `slot` to out[at], its descendants to out[next, ...) in depth
// first order (a node's children pair first, then the left child's descendants, then the
// right child's).
void compact_serial(const NodeSlots& slots, Bvh2Node* out, uint32_t slot, uint32_t at,
                    uint32_t next) {
  std::vector<std::pair<uint32_t, uint32_t>> stack;  // (slot, output index)
  stack.reserve(128);
  stack.push_back({slot, at});
  while (!stack.empty()) {
    auto [s, o] = stack.back();
    stack.pop_back();
    Bvh2Node node = slots[s];
    if (!node.is_leaf()) {
      const uint32_t pair = next;
      next += 2;
      stack.push_back({node.index + 1, pair + 1});
      stack.push_back({node.index, pair});
      node.index = pair;
    }
    out[o] = node;
  }
}

// The same placement, the two children's subtrees as parallel tasks: the right child's
// descendants start after the left child's, whose count the builder recorded.
void compact_parallel(const NodeSlots& slots, Bvh2Node* out, uint32_t slot, uint32_t at,
                      uint32_t next) {
  Bvh2Node node = slots[slot];
  if (node.is_leaf() || slots.subtree_nodes(slot) < compact_grain)
    return compact_serial(slots, out, slot, at, next);
  const uint32_t l = node.index, pair = next;
  node.index = pair;
  out[at] = node;
  const uint32_t right_next = pair + 2 + (slots.subtree_nodes(l) - 1);
  parallel_invoke([&] { compact_parallel(slots, out, l, pair, pair + 2); },
                  [&] { compact_parallel(slots, out, l + 1, pair + 1, right_next); });
}

}  // namespace

Bvh2 compact_slots(const NodeSlots& slots, std::span<const uint32_t> ordered_prim_ids) {
  Bvh2 out;
  out.prim_ids.assign(ordered_prim_ids.begin(), ordered_prim_ids.end());
  if (ordered_prim_ids.empty()) return out;
  out.nodes.resize(slots.subtree_nodes(0));
  if (current_thread_count() > 1)
    compact_parallel(slots, out.nodes.data(), 0, 0, 1);
  else
    compact_serial(slots, out.nodes.data(), 0, 0, 1);
  return out;
}

}  // namespace kestrel
