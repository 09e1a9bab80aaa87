#include "bvh/node_slots.h"

#include <cstdlib>
#include <new>
#include <vector>

namespace kestrel {

NodeSlots::NodeSlots(size_t prim_count) : slots_(2 * prim_count + 2) {}

Bvh2 compact_slots(NodeSlots& slots, std::span<const uint32_t> ordered_prim_ids) {
  Bvh2 out;
  out.prim_ids.assign(ordered_prim_ids.begin(), ordered_prim_ids.end());
  out.nodes.resize(2 * ordered_prim_ids.size() - 1);  // at most; trimmed below
  // (slot index, output index) pairs; depth first, left child first.
  std::vector<std::pair<uint32_t, uint32_t>> stack;
  stack.reserve(128);
  stack.push_back({0, 0});
  uint32_t next = 1;
  while (!stack.empty()) {
    auto [s, o] = stack.back();
    stack.pop_back();
    Bvh2Node node = slots[s];
    if (!node.is_leaf()) {
      uint32_t pair = next;
      next += 2;
      stack.push_back({node.index + 1, pair + 1});
      stack.push_back({node.index, pair});
      node.index = pair;
    }
    out.nodes[o] = node;
  }
  out.nodes.resize(next);
  return out;
}

}  // namespace kestrel
