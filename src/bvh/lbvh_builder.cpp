// Linear BVH: Morton codes of the centroids (30 bits = 10 per axis, or 63 = 21 per axis),
// a parallel radix sort, and the hierarchy emitted in parallel, one inner node per
// adjacent key pair, as in Karras 2012 ("Maximizing parallelism in the construction of
// BVHs, octrees, and k-d trees"). Equal codes are disambiguated by position, so duplicate
// centroids still give a valid tree. Bounds and SAH costs are then computed bottom-up and
// subtrees collapsed into leaves where the SAH prefers it (binary_tree.h).
#include <algorithm>
#include <bit>

#include "bvh/binary_tree.h"
#include "bvh/builders.h"
#include "bvh/radix_sort.h"
#include "core/parallel.h"
#include "core/vec.h"

namespace kestrel {

namespace {

// Spreads the low 10 bits of x so two zero bits separate each (for 30-bit codes).
inline uint32_t spread_bits_10(uint32_t x) {
  x &= 0x3FF;
  x = (x | (x << 16)) & 0x030000FF;
  x = (x | (x << 8)) & 0x0300F00F;
  x = (x | (x << 4)) & 0x030C30C3;
  x = (x | (x << 2)) & 0x09249249;
  return x;
}

// Spreads the low 21 bits of x (for 63-bit codes).
inline uint64_t spread_bits_21(uint64_t x) {
  x &= 0x1FFFFF;
  x = (x | (x << 32)) & 0x1F00000000FFFFull;
  x = (x | (x << 16)) & 0x1F0000FF0000FFull;
  x = (x | (x << 8)) & 0x100F00F00F00F00Full;
  x = (x | (x << 4)) & 0x10C30C30C30C30C3ull;
  x = (x | (x << 2)) & 0x1249249249249249ull;
  return x;
}

template <class Key>
Key morton_code(Vec3 q);
template <>
uint32_t morton_code<uint32_t>(Vec3 q) {
  return (spread_bits_10(uint32_t(q.x)) << 2) | (spread_bits_10(uint32_t(q.y)) << 1) |
         spread_bits_10(uint32_t(q.z));
}
template <>
uint64_t morton_code<uint64_t>(Vec3 q) {
  return (spread_bits_21(uint64_t(q.x)) << 2) | (spread_bits_21(uint64_t(q.y)) << 1) |
         spread_bits_21(uint64_t(q.z));
}

template <class Key>
struct KarrasHierarchy {
  const std::vector<Key>& keys;
  int64_t n;

  // Length of the common prefix of keys i and j (augmented by the index for equal keys),
  // or -1 when j is out of range.
  int delta(int64_t i, int64_t j) const {
    if (j < 0 || j >= n) return -1;
    Key a = keys[i], b = keys[j];
    if (a == b) return int(sizeof(Key) * 8) + std::countl_zero(uint32_t(i ^ j));
    return std::countl_zero(Key(a ^ b));
  }

  void emit(int64_t i, BinaryTree& tree) const {
    const int d = delta(i, i + 1) - delta(i, i - 1) >= 0 ? 1 : -1;
    const int delta_min = delta(i, i - d);
    int64_t l_max = 2;
    while (delta(i, i + l_max * d) > delta_min) l_max *= 2;
    int64_t l = 0;
    for (int64_t t = l_max / 2; t >= 1; t /= 2)
      if (delta(i, i + (l + t) * d) > delta_min) l += t;
    const int64_t j = i + l * d;
    const int delta_node = delta(i, j);
    int64_t s = 0;
    for (int64_t div = 2;; div *= 2) {
      int64_t t = (l + div - 1) / div;
      if (delta(i, i + (s + t) * d) > delta_node) s += t;
      if (t == 1) break;
    }
    const int64_t gamma = i + s * d + std::min(d, 0);
    const uint32_t left = std::min(i, j) == gamma ? uint32_t(gamma) | BinaryTree::leaf_bit : uint32_t(gamma);
    const uint32_t right =
        std::max(i, j) == gamma + 1 ? uint32_t(gamma + 1) | BinaryTree::leaf_bit : uint32_t(gamma + 1);
    tree.left[i] = left;
    tree.right[i] = right;
    // Each node has exactly one parent, so these writes never race.
    if (BinaryTree::is_leaf(left)) tree.leaf_parent[gamma] = uint32_t(i);
    else tree.parent[gamma] = uint32_t(i);
    if (BinaryTree::is_leaf(right)) tree.leaf_parent[gamma + 1] = uint32_t(i);
    else tree.parent[gamma + 1] = uint32_t(i);
  }
};

template <class Key>
void build_hierarchy(std::span<const PrimRef> refs, const BuildConfig& config, int bits_per_axis,
                     BinaryTree& tree) {
  const size_t n = refs.size();
  // Centroid bounds, reduced over fixed chunks.
  constexpr size_t chunk = 1u << 14;
  const size_t chunks = chunk_count(n, chunk);
  std::vector<Bounds3> partial(chunks);
  parallel_for(0, chunks, 1, [&](size_t cb, size_t ce) {
    for (size_t c = cb; c < ce; ++c)
      for (size_t i = c * chunk; i < std::min(n, (c + 1) * chunk); ++i)
        extend(partial[c], refs[i].lo + refs[i].hi);
  });
  Bounds3 cb;
  for (const Bounds3& p : partial) extend(cb, p);
  const float cells = float(1u << bits_per_axis);
  const Vec3 ext = extent(cb);
  const Vec3 scale{ext.x > 0 ? cells / ext.x : 0.0f, ext.y > 0 ? cells / ext.y : 0.0f,
                   ext.z > 0 ? cells / ext.z : 0.0f};
  const float top = cells - 1.0f;
  std::vector<Key> keys(n);
  std::vector<uint32_t> order(n);
  parallel_for(0, n, 16384, [&](size_t b, size_t e) {
    for (size_t i = b; i < e; ++i) {
      Vec3 q = (refs[i].lo + refs[i].hi - cb.lo) * scale;
      q = {std::clamp(q.x, 0.0f, top), std::clamp(q.y, 0.0f, top), std::clamp(q.z, 0.0f, top)};
      keys[i] = morton_code<Key>(q);
      order[i] = uint32_t(i);
    }
  });
  radix_sort(keys, order, 3 * bits_per_axis);

  tree.leaves.resize(n);
  parallel_for(0, n, 16384, [&](size_t b, size_t e) {
    for (size_t i = b; i < e; ++i) tree.leaves[i] = refs[order[i]];
  });
  const size_t inner = n - 1;
  tree.left.resize(inner);
  tree.right.resize(inner);
  tree.parent.resize(inner);
  tree.leaf_parent.resize(n);
  tree.bounds.resize(inner);
  tree.count.resize(inner);
  tree.cost.resize(inner);
  if (inner == 0) {
    tree.leaf_parent[0] = BinaryTree::no_parent;
    return;
  }
  tree.parent[0] = BinaryTree::no_parent;
  KarrasHierarchy<Key> h{keys, int64_t(n)};
  parallel_for(0, inner, 4096, [&](size_t b, size_t e) {
    for (size_t i = b; i < e; ++i) h.emit(int64_t(i), tree);
  });
  bottom_up(tree, config, nullptr, nullptr);
}

}  // namespace

BinaryTree build_lbvh_tree(std::span<const PrimRef> refs, const BuildConfig& config) {
  BinaryTree tree;
  if (config.morton_bits == 63) {
    build_hierarchy<uint64_t>(refs, config, 21, tree);
  } else {
    build_hierarchy<uint32_t>(refs, config, 10, tree);
  }
  return tree;
}

Bvh2 build_lbvh(std::span<const PrimRef> refs, const BuildConfig& config) {
  return emit_bvh2(build_lbvh_tree(refs, config), config);
}

}  // namespace kestrel
