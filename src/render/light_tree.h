// A BVH over the local lights (emissive triangles and point / spot lights) for choosing one
// by its estimated contribution at a shading point: Conty Estevez & Kulla 2018's light tree
// without the orientation cones. A node's importance at x is its power over the squared
// distance from x to its box's centre, the distance clamped below by the box's half
// diagonal (so a point inside a cluster does not divide by zero); one light is reached by a
// walk from the root that picks a child in proportion to importance.
#pragma once
#include <cstdint>
#include <vector>

#include "kestrel/types.h"

namespace kestrel::render {

class LightTree {
 public:
  struct Item {
    Bounds3 bounds;  ///< where the light is (a point light: a degenerate box)
    float power = 0;
  };
  /// Item i is local light i.
  void build(const std::vector<Item>& items);
  bool empty() const { return nodes_.empty(); }
  /// A light for point x and u in [0, 1), and the probability it had of being picked.
  size_t sample(Vec3 x, float u, float& pmf) const;
  /// The probability that sample() picks light i at x.
  float pmf(Vec3 x, size_t i) const;

 private:
  struct Node {
    Bounds3 box;
    float power = 0;
    int32_t left = -1, right = -1;  // children, or -1 for a leaf
    int32_t light = -1;             // a leaf's light
    int32_t parent = -1;
  };
  // An inner node's two children as importance needs them (one cache line per level).
  struct Children {
    float cx[2], cy[2], cz[2], r2[2], power[2];  // box centre, squared half diagonal, power
    int32_t child[2];
    int32_t light[2];  // a leaf child's light, else -1
  };
  // The probability of going to the left child of inner node `at` at x.
  float left_probability(size_t at, Vec3 x) const;
  int32_t build(std::vector<uint32_t>& ids, size_t begin, size_t end,
                const std::vector<Item>& items, int32_t parent);
  std::vector<Node> nodes_;
  std::vector<Children> children_;  // per node (unused for leaves)
  std::vector<int32_t> leaf_of_;
};

}  // namespace kestrel::render
