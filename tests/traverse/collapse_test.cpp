// The collapse of a binary BVH into wide nodes picks, for every wide node, the binary nodes
// that become its slots with the least wide SAH cost (a dynamic program over the binary tree).
// Checked against brute force: every admissible wide tree over the same binary tree, each
// wide node's slots enumerated as explicit sets, costed in double precision.
#include <gtest/gtest.h>

#include <algorithm>
#include <limits>
#include <vector>

#include "bvh/builders.h"
#include "geometry/prim_ref.h"
#include "kestrel/kestrel.h"
#include "support/oracles.h"
#include "traverse/wide_bvh.h"

namespace kestrel {
namespace {

double half_area(const Bvh2Node& n) {
  const double dx = double(n.hi.x) - n.lo.x, dy = double(n.hi.y) - n.lo.y,
               dz = double(n.hi.z) - n.lo.z;
  return dx * dy + dy * dz + dz * dx;
}

// Brute force over the wide trees a binary tree admits: a wide node at binary node n takes as
// its slots any set F of at most W nodes below n that covers n's subtree (a cut: every leaf of
// n's subtree under exactly one member), F != {n}; a subtree of at most four primitives is one
// leaf (of one block: what the collapse does with max_leaf 4) and cannot be cut.
class BruteForce {
 public:
  BruteForce(const Bvh2& bvh, int width) : bvh_(bvh), width_(width) {
    count_.resize(bvh.nodes.size());
    for (size_t i = bvh.nodes.size(); i-- > 0;) {  // children follow their parents
      const Bvh2Node& n = bvh.nodes[i];
      count_[i] = n.is_leaf() ? n.count : count_[n.index] + count_[n.index + 1];
    }
    best_.assign(bvh.nodes.size(), -1.0);
  }

  // wide_sah_cost's value: the root node's visit and its slots' costs over its area.
  double sah() { return inner(0) / half_area(bvh_.nodes[0]); }

 private:
  bool flat(uint32_t n) const { return count_[n] <= 4; }

  // Every cut of n's subtree with at most `limit` members, as explicit sets.
  std::vector<std::vector<uint32_t>> cuts(uint32_t n, int limit) const {
    std::vector<std::vector<uint32_t>> out{{n}};
    if (flat(n) || limit < 2) return out;
    const uint32_t l = bvh_.nodes[n].index;
    for (const auto& a : cuts(l, limit - 1))
      for (const auto& b : cuts(l + 1, limit - int(a.size()))) {
        std::vector<uint32_t> both = a;
        both.insert(both.end(), b.begin(), b.end());
        out.push_back(std::move(both));
      }
    return out;
  }

  // A slot's cost: a leaf's area (one block), or an inner wide node's.
  double slot(uint32_t n) { return flat(n) ? half_area(bvh_.nodes[n]) : inner(n); }

  // The least cost of a wide node at n: its visit (its area) plus its slots'.
  double inner(uint32_t n) {
    if (best_[n] >= 0) return best_[n];
    double best = std::numeric_limits<double>::infinity();
    for (const auto& cut : cuts(n, width_)) {
      if (cut.size() == 1) continue;  // {n} itself: not a wide node
      double sum = 0;
      for (uint32_t f : cut) sum += slot(f);
      best = std::min(best, sum);
    }
    return best_[n] = half_area(bvh_.nodes[n]) + best;
  }

  const Bvh2& bvh_;
  int width_;
  std::vector<uint32_t> count_;
  std::vector<double> best_;
};

TEST(Collapse, WideNodesTakeTheSlotsOfLeastSahCost) {
  for (uint64_t seed : {1u, 2u, 3u, 4u, 5u, 6u})
    for (size_t n : {9u, 40u, 90u}) {
      const Scene scene = test::random_soup(n, 0.3f, seed);
      BuildConfig c;
      c.builder = seed % 2 ? Builder::binned : Builder::median;
      c.max_leaf_size = 1;  // many binary levels below the blocks: many ways to cut
      SceneValidation validation;
      const Buffer<PrimRef> refs = validate_and_make_prim_refs(scene, validation);
      const Bvh2 bvh = build_bvh(refs, c);
      const Buffer<Triangle> tris = gather_triangles(scene, bvh.prim_ids);
      const Bvh4 four = collapse_to_bvh4(bvh, tris, 4);
      const Bvh8 eight = collapse_to_bvh8(bvh, tris, 4);
      const double want4 = BruteForce(bvh, 4).sah(), want8 = BruteForce(bvh, 8).sah();
      SCOPED_TRACE("seed " + std::to_string(seed) + ", " + std::to_string(n) + " triangles");
      EXPECT_NEAR(wide_sah_cost(four), want4, 1e-5 * want4);
      EXPECT_NEAR(wide_sah_cost(eight), want8, 1e-5 * want8);
    }
}

}  // namespace
}  // namespace kestrel
