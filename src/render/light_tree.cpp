// The light tree (light_tree.h): built by median splits of the light centres along the
// widest axis; sampled and evaluated with the same per-node probabilities.
#include "render/light_tree.h"

#include <algorithm>
#include <cmath>

#include "core/vec.h"

namespace kestrel::render {

void LightTree::build(const std::vector<Item>& items) {
  nodes_.clear();
  leaf_of_.assign(items.size(), -1);
  if (items.empty()) return;
  std::vector<uint32_t> ids(items.size());
  for (uint32_t i = 0; i < ids.size(); ++i) ids[i] = i;
  nodes_.reserve(2 * items.size());
  build(ids, 0, ids.size(), items, -1);
}

int32_t LightTree::build(std::vector<uint32_t>& ids, size_t begin, size_t end,
                         const std::vector<Item>& items, int32_t parent) {
  const int32_t index = int32_t(nodes_.size());
  nodes_.push_back(Node{});
  Node n;
  n.parent = parent;
  Bounds3 centres;
  for (size_t k = begin; k < end; ++k) {
    const Item& it = items[ids[k]];
    extend(n.box, it.bounds.lo), extend(n.box, it.bounds.hi);
    extend(centres, center(it.bounds));
    n.power += it.power;
  }
  if (end - begin == 1) {
    n.light = int32_t(ids[begin]);
    leaf_of_[ids[begin]] = index;
    nodes_[size_t(index)] = n;
    return index;
  }
  const Vec3 e = extent(centres);
  const int axis = e.x >= e.y && e.x >= e.z ? 0 : (e.y >= e.z ? 1 : 2);
  const size_t mid = begin + (end - begin) / 2;
  std::nth_element(ids.begin() + std::ptrdiff_t(begin), ids.begin() + std::ptrdiff_t(mid),
                   ids.begin() + std::ptrdiff_t(end), [&](uint32_t a, uint32_t b) {
                     const float ca = center(items[a].bounds)[axis],
                                 cb = center(items[b].bounds)[axis];
                     return ca < cb || (ca == cb && a < b);
                   });
  nodes_[size_t(index)] = n;  // children are appended after it
  const int32_t left = build(ids, begin, mid, items, index);
  const int32_t right = build(ids, mid, end, items, index);
  nodes_[size_t(index)].left = left, nodes_[size_t(index)].right = right;
  return index;
}

float LightTree::importance(const Node& n, Vec3 x) const {
  const Vec3 c = center(n.box), d = x - c, half = extent(n.box) * 0.5f;
  const float dist2 = std::max(dot(d, d), dot(half, half));
  return dist2 > 0 ? n.power / dist2 : n.power * 1e30f;
}

float LightTree::left_probability(const Node& n, Vec3 x) const {
  const float l = importance(nodes_[size_t(n.left)], x), r = importance(nodes_[size_t(n.right)], x);
  const float sum = l + r;
  return sum > 0 && std::isfinite(sum) ? l / sum : 0.5f;
}

size_t LightTree::sample(Vec3 x, float u, float& pmf) const {
  pmf = 1;
  size_t at = 0;
  while (nodes_[at].left >= 0) {
    const Node& n = nodes_[at];
    const float p = left_probability(n, x);
    if (u < p) {
      u = std::min(u / p, 0.99999994f);
      pmf *= p;
      at = size_t(n.left);
    } else {
      u = std::min((u - p) / (1 - p), 0.99999994f);
      pmf *= 1 - p;
      at = size_t(n.right);
    }
  }
  return size_t(nodes_[at].light);
}

float LightTree::pmf(Vec3 x, size_t i) const {
  if (i >= leaf_of_.size() || leaf_of_[i] < 0) return 0;
  float pmf = 1;
  int32_t child = leaf_of_[i];
  for (int32_t at = nodes_[size_t(child)].parent; at >= 0;
       child = at, at = nodes_[size_t(at)].parent) {
    const Node& n = nodes_[size_t(at)];
    const float p = left_probability(n, x);
    pmf *= n.left == child ? p : 1 - p;
  }
  return pmf;
}

}  // namespace kestrel::render
