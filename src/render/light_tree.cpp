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
  children_.assign(nodes_.size(), Children{});
  for (size_t i = 0; i < nodes_.size(); ++i) {
    if (nodes_[i].left < 0) continue;
    Children& c = children_[i];
    for (int k = 0; k < 2; ++k) {
      const Node& n = nodes_[size_t(k ? nodes_[i].right : nodes_[i].left)];
      const Vec3 m = center(n.box), half = extent(n.box) * 0.5f;
      c.cx[k] = m.x, c.cy[k] = m.y, c.cz[k] = m.z, c.r2[k] = dot(half, half);
      c.power[k] = n.power;
      c.child[k] = k ? nodes_[i].right : nodes_[i].left;
      c.light[k] = n.left < 0 ? n.light : -1;
    }
  }
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

// importance_k = power_k / max(|x - centre_k|^2, r2_k); the left child's share of the two,
// with one division: power_0 d_1 / (power_0 d_1 + power_1 d_0).
namespace {
template <class Children>
inline __attribute__((always_inline)) float split(const Children& c, Vec3 x) {
  float d[2];
  for (int k = 0; k < 2; ++k) {
    const float dx = x.x - c.cx[k], dy = x.y - c.cy[k], dz = x.z - c.cz[k];
    d[k] = std::max(dx * dx + dy * dy + dz * dz, c.r2[k]);
  }
  const float a = c.power[0] * d[1], sum = a + c.power[1] * d[0];
  return sum > 0 && sum < INFINITY ? a / sum : 0.5f;
}
}  // namespace

float LightTree::left_probability(size_t at, Vec3 x) const {
  return split(children_[at], x);
}

size_t LightTree::sample(Vec3 x, float u, float& pmf) const {
  pmf = 1;
  if (nodes_[0].left < 0) return size_t(nodes_[0].light);
  const Children* all = children_.data();
  for (size_t at = 0;;) {
    const Children& c = all[at];
    const float p = split(c, x);
    const bool right = !(u < p);
    const float share = right ? 1 - p : p;
    u = std::min((right ? u - p : u) / share, 0.99999994f);
    pmf *= share;
    const int32_t light = c.light[right], child = c.child[right];
    if (light >= 0) return size_t(light);
    at = size_t(child);
  }
}

float LightTree::pmf(Vec3 x, size_t i) const {
  if (i >= leaf_of_.size() || leaf_of_[i] < 0) return 0;
  float pmf = 1;
  int32_t child = leaf_of_[i];
  for (int32_t at = nodes_[size_t(child)].parent; at >= 0;
       child = at, at = nodes_[size_t(at)].parent) {
    const float p = left_probability(size_t(at), x);
    pmf *= nodes_[size_t(at)].left == child ? p : 1 - p;
  }
  return pmf;
}

}  // namespace kestrel::render
