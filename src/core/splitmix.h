// SplitMix64 (Steele, Lea & Flood 2014): a tiny, well-mixed generator with a fixed stream per
// seed on every machine and compiler — for generated scenes and rays, not for sampling.
#pragma once
#include <cstdint>

namespace kestrel {

struct SplitMix64 {
  uint64_t state;
  uint64_t next() {
    uint64_t z = (state += 0x9E3779B97F4A7C15ull);
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
    return z ^ (z >> 31);
  }
  float uniform() { return float(next() >> 40) * (1.0f / 16777216.0f); }  ///< [0, 1)
};

}  // namespace kestrel
