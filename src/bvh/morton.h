// Morton-code bit spreading (interleaving three coordinates), for LBVH and the instance tree.
#pragma once
#include <cstdint>

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

}  // namespace kestrel
