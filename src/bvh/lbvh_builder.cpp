// Linear BVH: Morton codes of the centroids (30 bits = 10 per axis, or 63 = 21 per axis),
// a parallel radix sort, and the hierarchy of Karras 2012 ("Maximizing parallelism in the
// construction of BVHs, octrees, and k-d trees"): inner node i separates sorted keys i and
// i + 1, and every node splits its key range where its highest differing bit flips. Equal
// codes are disambiguated by position (key, index), so duplicates still give a valid tree.
//
// The hierarchy is emitted bottom-up in the same pass that computes bounds and SAH costs
// (the agglomerative order of Apetrei 2014): a range [l, r] joins the neighbouring
// boundary, l - 1 or r, across which fewer leading bits differ; the second child to reach
// a node continues upwards. In a sorted key sequence the highest differing bit of two
// boundaries is never the same, so this is exactly Karras' topology (the tests check it
// against the top-down binary-search emission below) -- with no binary searches and one
// pass over the nodes instead of two. Subtrees are then collapsed into leaves where the
// SAH prefers it (binary_tree.h).
#include <algorithm>
#include <atomic>
#include <bit>
#include <new>
#include <utility>

#include "bvh/binary_tree.h"
#include "bvh/builders.h"
#include "bvh/morton.h"
#include "bvh/radix_sort.h"
#include "core/parallel.h"
#include "core/vec.h"

namespace kestrel {

namespace {

// "Distance" of the keys across boundary i (between sorted keys i and i + 1): the xor of
// the (key, index) pairs, compared lexicographically. Smaller = longer common prefix.
template <class Key>
struct Boundary {
  Key key_xor;
  uint32_t index_xor;
  bool operator<(const Boundary& o) const {
    return key_xor < o.key_xor || (key_xor == o.key_xor && index_xor < o.index_xor);
  }
};

template <class Key>
struct SortedKeys {
  const Key* keys;
  uint32_t n;
  Boundary<Key> at(uint32_t i) const { return {Key(keys[i] ^ keys[i + 1]), i ^ (i + 1)}; }
  // Karras' delta: length of the common prefix of (key, index) at i and j; -1 out of range.
  int delta(int64_t i, int64_t j) const {
    if (j < 0 || j >= int64_t(n)) return -1;
    const Key a = keys[i], b = keys[j];
    if (a == b) return int(sizeof(Key) * 8) + std::countl_zero(uint32_t(i ^ j));
    return std::countl_zero(Key(a ^ b));
  }
};

constexpr uint32_t no_bound = 0xFFFFFFFFu;

inline void set_parent(BinaryTree& tree, uint32_t child, uint32_t parent) {
  if (BinaryTree::is_leaf(child))
    tree.leaf_parent[BinaryTree::leaf_index(child)] = parent;
  else
    tree.parent[child] = parent;
}

// One leaf's walk up the tree (see the file comment). `Exchange` swaps the outer bound left
// at a node: an atomic exchange when walks run in parallel, a plain swap when serial.
template <class Key, class Exchange>
inline void walk_up(const SortedKeys<Key>& sk, BinaryTree& tree, const BuildConfig& config,
                    uint32_t i, Exchange&& exchange) {
  const uint32_t n = sk.n;
  uint32_t l = i, r = i, node = i | BinaryTree::leaf_bit;
  while (true) {
    if (l == 0 && r == n - 1) {
      tree.root = node;
      set_parent(tree, node, BinaryTree::no_parent);
      return;
    }
    const bool join_right = l == 0 || (r != n - 1 && sk.at(r) < sk.at(l - 1));
    const uint32_t parent = join_right ? r : l - 1;
    (join_right ? tree.left : tree.right)[parent] = node;
    set_parent(tree, node, parent);
    // The first child to arrive leaves its outer bound and stops; the second takes it.
    const uint32_t bound = exchange(parent, join_right ? l : r);
    if (bound == no_bound) return;
    (join_right ? r : l) = bound;
    node = parent;
    refit_node(tree, parent, config);
  }
}

template <class Key>
void emit_bottom_up(const SortedKeys<Key>& sk, BinaryTree& tree, const BuildConfig& config) {
  const uint32_t n = sk.n;
  if (current_thread_count() == 1) {
    // Serial: the same walks in the same order, without atomic read-modify-writes.
    RawArray<uint32_t> other(n - 1);
    std::fill(other.begin(), other.end(), no_bound);
    for (uint32_t i = 0; i < n; ++i)
      walk_up(sk, tree, config, i,
              [&](uint32_t node, uint32_t bound) { return std::exchange(other[node], bound); });
    return;
  }
  RawArray<std::atomic<uint32_t>> other(n - 1);
  parallel_for(0, n - 1, 65536, [&](size_t b, size_t e) {
    for (size_t i = b; i < e; ++i) new (&other[i]) std::atomic<uint32_t>(no_bound);
  });
  parallel_for(0, n, 8192, [&](size_t b, size_t e) {
    for (uint32_t i = uint32_t(b); i < uint32_t(e); ++i)
      walk_up(sk, tree, config, i, [&](uint32_t node, uint32_t bound) {
        // acq_rel: the second walk also sees everything the first wrote below the node.
        return other[node].exchange(bound, std::memory_order_acq_rel);
      });
  });
}

// Top-down emission with binary searches (Karras 2012, Figure 4), then bounds bottom-up.
template <class Key>
void emit_top_down(const SortedKeys<Key>& sk, BinaryTree& tree, const BuildConfig& config) {
  const int64_t n = sk.n;
  parallel_for(0, size_t(n - 1), 4096, [&](size_t b, size_t e) {
    for (int64_t i = int64_t(b); i < int64_t(e); ++i) {
      const int d = sk.delta(i, i + 1) - sk.delta(i, i - 1) >= 0 ? 1 : -1;
      const int delta_min = sk.delta(i, i - d);
      int64_t l_max = 2;
      while (sk.delta(i, i + l_max * d) > delta_min) l_max *= 2;
      int64_t l = 0;
      for (int64_t t = l_max / 2; t >= 1; t /= 2)
        if (sk.delta(i, i + (l + t) * d) > delta_min) l += t;
      const int64_t j = i + l * d;
      const int delta_node = sk.delta(i, j);
      int64_t s = 0;
      for (int64_t div = 2;; div *= 2) {
        const int64_t t = (l + div - 1) / div;
        if (sk.delta(i, i + (s + t) * d) > delta_node) s += t;
        if (t == 1) break;
      }
      const int64_t gamma = i + s * d + std::min(d, 0);
      const uint32_t left =
          std::min(i, j) == gamma ? uint32_t(gamma) | BinaryTree::leaf_bit : uint32_t(gamma);
      const uint32_t right = std::max(i, j) == gamma + 1
                                 ? uint32_t(gamma + 1) | BinaryTree::leaf_bit
                                 : uint32_t(gamma + 1);
      tree.left[i] = left;
      tree.right[i] = right;
      set_parent(tree, left, uint32_t(i));  // one parent per node: no races
      set_parent(tree, right, uint32_t(i));
    }
  });
  tree.root = 0;
  tree.parent[0] = BinaryTree::no_parent;
  bottom_up(tree, config, nullptr, nullptr);
}

template <class Key>
BinaryTree build_tree(std::span<const PrimRef> refs, const BuildConfig& config, bool top_down) {
  const size_t n = refs.size();
  BinaryTree tree;
  tree.allocate(n);
  RawArray<Key> keys;
  RawArray<uint32_t> order;
  morton_sort(refs, MortonValue::index, keys, order);
  parallel_for(0, n, 16384, [&](size_t b, size_t e) {
    for (size_t i = b; i < e; ++i) tree.leaves[i] = refs[order[i]];
  });
  if (n == 1) {
    tree.root = BinaryTree::leaf_bit;
    tree.leaf_parent[0] = BinaryTree::no_parent;
    return tree;
  }
  const SortedKeys<Key> sk{keys.data(), uint32_t(n)};
  if (top_down)
    emit_top_down(sk, tree, config);
  else
    emit_bottom_up(sk, tree, config);
  return tree;
}

BinaryTree build_any(std::span<const PrimRef> refs, const BuildConfig& config, bool top_down) {
  return config.morton_bits == 63 ? build_tree<uint64_t>(refs, config, top_down)
                                  : build_tree<uint32_t>(refs, config, top_down);
}

}  // namespace

Bounds3 centroid_bounds(std::span<const PrimRef> refs) {
  constexpr size_t chunk = 1u << 14;
  const size_t n = refs.size(), chunks = chunk_count(n, chunk);
  std::vector<Bounds3> partial(chunks);
  parallel_for(0, chunks, 1, [&](size_t cb, size_t ce) {
    for (size_t c = cb; c < ce; ++c)
      for (size_t i = c * chunk; i < std::min(n, (c + 1) * chunk); ++i)
        extend(partial[c], refs[i].lo + refs[i].hi);
  });
  Bounds3 b;
  for (const Bounds3& p : partial) extend(b, p);
  return b;
}

template <class Key>
void morton_sort(std::span<const PrimRef> refs, MortonValue value, RawArray<Key>& keys,
                 RawArray<uint32_t>& values, const Bounds3* centroids) {
  const size_t n = refs.size();
  const MortonQuantizer<Key> code(centroids ? *centroids : centroid_bounds(refs));
  keys.resize(n);
  values.resize(n);
  auto value_of = [&](size_t i) {
    return value == MortonValue::index ? uint32_t(i) : refs[i].prim_id;
  };
  if constexpr (sizeof(Key) == 4) {
    // The codes go straight into the sort's packed records (code << 32 | value): no keys and
    // values written first and packed in another pass.
    RawArray<uint64_t> records(n);
    parallel_for(0, n, 16384, [&](size_t b, size_t e) {
      for (size_t i = b; i < e; ++i) records[i] = uint64_t(code(refs[i])) << 32 | value_of(i);
    });
    radix_sort_packed_pairs(records, 3 * code.bits_per_axis);
    parallel_for(0, n, 16384, [&](size_t b, size_t e) {
      for (size_t i = b; i < e; ++i)
        keys[i] = Key(records[i] >> 32), values[i] = uint32_t(records[i]);
    });
  } else {
    parallel_for(0, n, 16384, [&](size_t b, size_t e) {
      for (size_t i = b; i < e; ++i) keys[i] = code(refs[i]), values[i] = value_of(i);
    });
    radix_sort(keys, values, 3 * code.bits_per_axis);
  }
}
template void morton_sort<uint32_t>(std::span<const PrimRef>, MortonValue, RawArray<uint32_t>&,
                                    RawArray<uint32_t>&, const Bounds3*);
template void morton_sort<uint64_t>(std::span<const PrimRef>, MortonValue, RawArray<uint64_t>&,
                                    RawArray<uint32_t>&, const Bounds3*);

BinaryTree build_lbvh_tree(std::span<const PrimRef> refs, const BuildConfig& config) {
  return build_any(refs, config, /* top_down = */ false);
}

BinaryTree build_lbvh_tree_karras(std::span<const PrimRef> refs, const BuildConfig& config) {
  return build_any(refs, config, /* top_down = */ true);
}

Bvh2 build_lbvh(std::span<const PrimRef> refs, const BuildConfig& config, bool block_leaves) {
  return emit_bvh2(build_lbvh_tree(refs, config), config, block_leaves ? 4u : 0u);
}

}  // namespace kestrel
