// Parallel least-significant-digit radix sort of (key, value) pairs, stable, 11-bit digits.
// Chunks are fixed by size, not by thread, so the output never depends on the thread count.
#pragma once
#include <cstdint>
#include "core/raw_array.h"

namespace kestrel {

/// Sorts keys ascending (low `key_bits` bits significant), permuting values alongside.
void radix_sort(RawArray<uint32_t>& keys, RawArray<uint32_t>& values, int key_bits);
/// 64-bit keys (e.g. 63-bit Morton codes).
void radix_sort(RawArray<uint64_t>& keys, RawArray<uint32_t>& values, int key_bits);

}  // namespace kestrel
