// Morton-code bit spreading (interleaving three coordinates), for LBVH and the instance tree.
#pragma once
#include <bit>
#include <cstdint>
#include <span>

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

/// Bounds of the doubled centroids (lo + hi) of the refs: what Morton codes quantise.
/// Reduced over fixed chunks, in parallel (the same result for any thread count).
Bounds3 centroid_bounds(std::span<const PrimRef> refs);

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
