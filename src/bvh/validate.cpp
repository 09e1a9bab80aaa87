// Structural validation of a Bvh2 against the references it was built from.
#include <fmt/format.h>

#include <unordered_map>

#include "core/vec.h"
#include "kestrel/bvh.h"

namespace kestrel {

std::string validate_bvh(const Bvh2& bvh, std::span<const PrimRef> refs, uint32_t max_leaf_size,
                         bool split_references) {
  if (bvh.empty())
    return refs.empty() ? "" : fmt::format("empty BVH over {} references", refs.size());
  if (split_references ? bvh.prim_ids.size() < refs.size() : bvh.prim_ids.size() != refs.size())
    return fmt::format("{} prim ids for {} references", bvh.prim_ids.size(), refs.size());
  std::unordered_map<uint32_t, size_t> ref_of;
  ref_of.reserve(refs.size());
  for (size_t i = 0; i < refs.size(); ++i)
    if (!ref_of.emplace(refs[i].prim_id, i).second)
      return fmt::format("duplicate prim id {} in references", refs[i].prim_id);
  std::vector<uint8_t> node_seen(bvh.nodes.size(), 0), slot_seen(bvh.prim_ids.size(), 0),
      prim_seen(refs.size(), 0);
  std::vector<uint32_t> stack{0};
  node_seen[0] = 1;
  size_t visited = 0;
  while (!stack.empty()) {
    const uint32_t i = stack.back();
    stack.pop_back();
    ++visited;
    const Bvh2Node& node = bvh.nodes[i];
    const Bounds3 box{node.lo, node.hi};
    if (node.is_leaf()) {
      if (node.count > max_leaf_size)
        return fmt::format("leaf {} holds {} > {} primitives", i, node.count, max_leaf_size);
      if (size_t(node.index) + node.count > bvh.prim_ids.size())
        return fmt::format("leaf {} range [{}, +{}) past {} prim ids", i, node.index, node.count,
                           bvh.prim_ids.size());
      for (uint32_t k = node.index; k < node.index + node.count; ++k) {
        if (slot_seen[k]++) return fmt::format("prim id slot {} referenced by two leaves", k);
        auto it = ref_of.find(bvh.prim_ids[k]);
        if (it == ref_of.end())
          return fmt::format("leaf {} holds unknown prim id {}", i, bvh.prim_ids[k]);
        const PrimRef& r = refs[it->second];
        if (split_references) {
          for (uint32_t j = node.index; j < k; ++j)
            if (bvh.prim_ids[j] == r.prim_id)
              return fmt::format("leaf {} holds prim id {} twice", i, r.prim_id);
          prim_seen[it->second] = 1;
          if (is_empty(Bounds3{max(box.lo, r.lo), min(box.hi, r.hi)}))
            return fmt::format("leaf {} box does not touch prim {}", i, r.prim_id);
          continue;
        }
        if (prim_seen[it->second]++)
          return fmt::format("prim id {} appears twice", bvh.prim_ids[k]);
        if (!contains(box, Bounds3{r.lo, r.hi}))
          return fmt::format("leaf {} box does not enclose prim {}", i, r.prim_id);
      }
      continue;
    }
    if (size_t(node.index) + 1 >= bvh.nodes.size() || node.index == 0)
      return fmt::format("node {} children index {} out of range", i, node.index);
    for (uint32_t c = node.index; c <= node.index + 1; ++c) {
      if (node_seen[c]++) return fmt::format("node {} reached twice (cycle or shared child)", c);
      const Bvh2Node& child = bvh.nodes[c];
      if (!contains(box, Bounds3{child.lo, child.hi}))
        return fmt::format("node {} box not inside its parent {}", c, i);
      stack.push_back(c);
    }
  }
  if (visited != bvh.nodes.size())
    return fmt::format("{} of {} nodes unreachable", bvh.nodes.size() - visited, bvh.nodes.size());
  for (size_t i = 0; i < refs.size(); ++i)
    if (!prim_seen[i]) return fmt::format("prim id {} missing", refs[i].prim_id);
  return "";
}

}  // namespace kestrel
