// Morton-code bit spreading (interleaving three coordinates), for LBVH and the instance tree.
#pragma once
#include <bit>
#include <cstdint>
#include <span>

#include "core/raw_array.h"
#include "core/vec.h"
#include "kestrel/bvh.h"

namespace kestrel {

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

/// 30-bit Morton code of cell coordinates in [0, 1024).
inline uint32_t morton30(uint32_t x, uint32_t y, uint32_t z) {
  return (spread_bits_10(x) << 2) | (spread_bits_10(y) << 1) | spread_bits_10(z);
}

/// 63-bit Morton code of cell coordinates in [0, 2^21).
inline uint64_t morton63(uint64_t x, uint64_t y, uint64_t z) {
  return (spread_bits_21(x) << 2) | (spread_bits_21(y) << 1) | spread_bits_21(z);
}

/// Bounds of the doubled centroids (lo + hi) of the refs: what Morton codes quantise.
/// Reduced over fixed chunks, in parallel (the same result for any thread count).
Bounds3 centroid_bounds(std::span<const PrimRef> refs);

/// The Morton code of a ref's centroid: 2^10 (uint32_t keys, 30 bits) or 2^21 (uint64_t keys,
/// 63 bits) cells per axis over the centroid bounds (centroid_bounds). Both LBVH builds sort
/// by it.
template <class Key>
struct MortonQuantizer {
  static constexpr int bits_per_axis = sizeof(Key) == 4 ? 10 : 21;
  Vec3 lo, scale;
  float last_cell;
  explicit MortonQuantizer(const Bounds3& centroids) : lo(centroids.lo) {
    const float cells = float(1u << bits_per_axis);
    const Vec3 ext = extent(centroids);
    scale = {ext.x > 0 ? cells / ext.x : 0.0f, ext.y > 0 ? cells / ext.y : 0.0f,
             ext.z > 0 ? cells / ext.z : 0.0f};
    last_cell = cells - 1.0f;
  }
  // v > 0 ? v : 0, not a clamp: a NaN maps to cell 0 (refs are finite; this keeps the
  // conversion to an integer defined whatever comes in).
  float cell(float v) const {
    v = v > 0.0f ? v : 0.0f;
    return v < last_cell ? v : last_cell;
  }
  Key operator()(const PrimRef& r) const {
    const Vec3 q = (r.lo + r.hi - lo) * scale;
    if constexpr (sizeof(Key) == 4)
      return morton30(uint32_t(cell(q.x)), uint32_t(cell(q.y)), uint32_t(cell(q.z)));
    else
      return morton63(uint64_t(cell(q.x)), uint64_t(cell(q.y)), uint64_t(cell(q.z)));
  }
};

/// What rides along the Morton sort: each ref's position in `refs`, or its prim id.
enum class MortonValue { index, prim_id };
/// The refs' Morton codes (MortonQuantizer over their centroid bounds), sorted ascending into
/// `keys`, with `values` permuted alongside (a stable parallel radix sort: equal codes keep
/// the refs' order). Key: uint32_t (30 bits) or uint64_t (63 bits).
/// `centroids`: the refs' centroid bounds when the caller has them (validate_and_make_prim_refs
/// computes them in its pass), else computed here.
template <class Key>
void morton_sort(std::span<const PrimRef> refs, MortonValue value, RawArray<Key>& keys,
                 RawArray<uint32_t>& values, const Bounds3* centroids = nullptr);

/// Where a node over sorted keys [b, e) (e - b >= 2) splits (Karras 2012): the first index
/// whose key has the highest bit in which keys[b] and keys[e - 1] differ set; the middle when
/// all keys are equal. The keys of [b, e) share every bit above that one and are sorted, so
/// those with it clear come first. A branch-free binary search: the branchy one mispredicted
/// about every other step.
template <class Key>
inline uint32_t morton_split(const Key* keys, uint32_t b, uint32_t e) {
  const Key x = keys[b] ^ keys[e - 1];
  if (x == 0) return b + (e - b) / 2;
  const int bit = int(sizeof(Key) * 8) - 1 - std::countl_zero(x);
  const Key* base = keys + b;  // the last key with the bit clear is in [base, base + len)
  uint32_t len = e - b;
  while (len > 1) {
    const uint32_t half = len / 2;
    base = ((base[half] >> bit) & 1u) ? base : base + half;
    len -= half;
  }
  return uint32_t(base - keys) + 1;
}

}  // namespace kestrel
