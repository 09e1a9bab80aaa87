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
  wide_.clear();
  slot_.assign(items.size(), {-1, 0});
  if (nodes_[0].left >= 0) make_wide(0, -1, 0);
}

// The wide node for binary inner node `node`: its grandchildren (or children that are leaves).
int32_t LightTree::make_wide(int32_t node, int32_t parent, int32_t slot) {
  const int32_t index = int32_t(wide_.size());
  wide_.push_back(Wide{});
  int32_t kids[4];
  int n = 0;
  for (int32_t c : {nodes_[size_t(node)].left, nodes_[size_t(node)].right}) {
    const Node& cn = nodes_[size_t(c)];
    if (cn.left < 0) {
      kids[n++] = c;
    } else {
      kids[n++] = cn.left;
      kids[n++] = cn.right;
    }
  }
  Wide w;
  w.parent = parent, w.slot = slot, w.count = n;
  for (int k = 0; k < 4; ++k) {
    w.cx[k] = w.cy[k] = w.cz[k] = w.r2[k] = w.power[k] = 0;
    w.child[k] = -1;
  }
  for (int k = 0; k < n; ++k) {
    const Node& cn = nodes_[size_t(kids[k])];
    const Vec3 m = center(cn.box), half = extent(cn.box) * 0.5f;
    w.cx[k] = m.x, w.cy[k] = m.y, w.cz[k] = m.z, w.r2[k] = dot(half, half);
    w.power[k] = cn.power;
    if (cn.left < 0) {
      w.child[k] = -1 - cn.light;
      slot_[size_t(cn.light)] = {index, k};
    }
  }
  wide_[size_t(index)] = w;
  for (int k = 0; k < n; ++k)
    if (nodes_[size_t(kids[k])].left >= 0) {
      const int32_t child = make_wide(kids[k], index, k);
      wide_[size_t(index)].child[k] = child;
    }
  return index;
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

// importance_k = power_k / max(|x - centre_k|^2, r2_k) (an unused slot has power 0), the
// four children at once (each lane's operations in the order of one child's), summed in
// child order.
float LightTree::importances(const Wide& w, Vec3 x, float imp[4]) const {
  typedef float v4 __attribute__((vector_size(16)));
  typedef float v4u __attribute__((vector_size(16), aligned(4)));
  const auto load = [](const float* p) { return *reinterpret_cast<const v4u*>(p); };
  const v4 dx = x.x - load(w.cx), dy = x.y - load(w.cy), dz = x.z - load(w.cz);
  const v4 d2 = dx * dx + dy * dy + dz * dz, r2 = load(w.r2), power = load(w.power);
  const v4 d = d2 < r2 ? r2 : d2;  // std::max(d2, r2)
  const v4 q = d > 0 ? power / d : power * 1e30f;
  *reinterpret_cast<v4u*>(imp) = q;
  return ((q[0] + q[1]) + q[2]) + q[3];
}

// The child is the first whose running sum of importances passes u's share of their sum (at
// most the last), found without a branch per child: the running sums never decrease, so it
// is the count of those that do not pass it.
inline int32_t LightTree::step(const Wide& w, Vec3 x, float& u, float& pmf) const {
  float imp[4];
  const float sum = importances(w, x, imp);
  const int n = w.count;
  int k = 0;
  float share = 0;
  if (sum > 0 && sum < INFINITY) {
    const float target = u * sum;
    const float before_k[4] = {0.0f, imp[0], imp[0] + imp[1], (imp[0] + imp[1]) + imp[2]};
    k = int(before_k[1] <= target) + (int(before_k[2] <= target) & int(n > 2)) +
        (int(before_k[3] <= target) & int(n > 3));
    float before = before_k[k];
    while (imp[k] <= 0 && k > 0) before -= imp[--k];  // rounding past the last nonzero one
    share = imp[k] / sum;
    u = std::clamp((target - before) / imp[k], 0.0f, 0.99999994f);
  } else {  // degenerate importances: uniform over the children
    k = std::min(int(u * float(n)), n - 1);
    share = 1.0f / float(n);
    u = std::min(u * float(n) - float(k), 0.99999994f);
  }
  pmf *= share;
  return w.child[k];
}

size_t LightTree::sample(Vec3 x, float u, float& pmf) const {
  pmf = 1;
  if (wide_.empty()) return size_t(nodes_[0].light);
  for (size_t at = 0;;) {
    const int32_t c = step(wide_[at], x, u, pmf);
    if (c < 0) return size_t(-1 - c);
    at = size_t(c);
  }
}

void LightTree::sample(Vec3 x, const float* u, size_t n, uint32_t* light, float* pmf) const {
  if (wide_.empty()) {  // one light
    for (size_t i = 0; i < n; ++i) light[i] = uint32_t(nodes_[0].light), pmf[i] = 1;
    return;
  }
  for (size_t i0 = 0; i0 < n; i0 += 4) {
    const size_t m = std::min<size_t>(4, n - i0);
    int32_t at[4] = {0, 0, 0, 0};
    float uj[4] = {0, 0, 0, 0}, pj[4] = {1, 1, 1, 1};
    unsigned walking = (1u << m) - 1;
    for (size_t j = 0; j < m; ++j) uj[j] = u[i0 + j];
    while (walking) {
      for (unsigned j = 0; j < 4; ++j) {
        if (!(walking >> j & 1u)) continue;
        const int32_t c = step(wide_[size_t(at[j])], x, uj[j], pj[j]);
        if (c >= 0) {
          at[j] = c;
        } else {
          light[i0 + j] = uint32_t(-1 - c), pmf[i0 + j] = pj[j];
          walking &= ~(1u << j);
        }
      }
    }
  }
}

float LightTree::pmf(Vec3 x, size_t i) const {
  if (i >= leaf_of_.size() || leaf_of_[i] < 0) return 0;
  if (wide_.empty()) return 1;
  float pmf = 1;
  for (auto [at, slot] = slot_[i]; at >= 0;) {
    const Wide& w = wide_[size_t(at)];
    float imp[4];
    const float sum = importances(w, x, imp);
    if (sum > 0 && sum < INFINITY) {
      pmf *= imp[slot] / sum;
    } else {
      pmf *= 1.0f / float(w.count);
    }
    slot = w.slot, at = w.parent;
  }
  return pmf;
}

}  // namespace kestrel::render
