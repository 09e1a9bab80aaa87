// A BVH over the local lights (emissive triangles and point / spot lights) for choosing one
// by its estimated contribution at a shading point: Conty Estevez & Kulla 2018's light tree
// without the orientation cones. A node's importance at x is its power over the squared
// distance from x to its box's centre, the distance clamped below by the box's half
// diagonal (so a point inside a cluster does not divide by zero); one light is reached by a
// walk from the root that picks a child in proportion to importance, over 4-wide nodes (a
// binary tree built by median splits, read two levels at a time).
#pragma once
#include <cstdint>
#include <utility>
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
  /// sample(x, u[i], pmf[i]) into light[i] for each of n values of u at one point: the walks
  /// advance together, four at a time, so that their chains of dependent loads and divisions
  /// overlap (the same lights and probabilities as one at a time).
  void sample(Vec3 x, const float* u, size_t n, uint32_t* light, float* pmf) const;
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
  // The walk runs over 4-wide nodes (the binary tree's nodes two levels at a time): half the
  // steps, the four importances of a step independent of one another.
  struct Wide {
    float cx[4], cy[4], cz[4], r2[4], power[4];  // box centre, squared half diagonal, power
    int32_t child[4];                            // a wide node, or -1 - light for a light
    int32_t count = 0;                           // children used (2 to 4)
    int32_t parent = -1, slot = 0;               // where this node sits in its parent
  };
  // Importances of a wide node's children at x; returns their sum.
  float importances(const Wide& w, Vec3 x, float imp[4]) const;
  // One step of a walk at x: the child of w that u picks (a wide node, or -1 - light), u
  // rescaled to the child's share and pmf multiplied by it.
  int32_t step(const Wide& w, Vec3 x, float& u, float& pmf) const;
  int32_t make_wide(int32_t node, int32_t parent, int32_t slot);
  int32_t build(std::vector<uint32_t>& ids, size_t begin, size_t end,
                const std::vector<Item>& items, int32_t parent);
  std::vector<Node> nodes_;
  std::vector<Wide> wide_;
  std::vector<int32_t> leaf_of_;                   // light -> binary leaf node
  std::vector<std::pair<int32_t, int32_t>> slot_;  // light -> (wide node, slot)
};

}  // namespace kestrel::render
