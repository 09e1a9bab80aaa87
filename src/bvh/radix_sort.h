// Parallel least-significant-digit radix sort of (key, value) pairs, stable, 11-bit digits.
// Chunks are fixed by size, not by thread, so the output never depends on the thread count.
#pragma once
#include <cstdint>
#include "core/raw_array.h"

namespace kestrel {

/// Sorts 64-bit keys ascending (low `key_bits` bits significant, e.g. 63-bit Morton codes),
/// permuting values alongside.
void radix_sort(RawArray<uint64_t>& keys, RawArray<uint32_t>& values, int key_bits);
/// 32-bit keys with their values, packed by the caller as (key << 32 | value) records (one
/// 8-byte record per element, as it writes them), sorted by the key's low `key_bits` bits.
void radix_sort_packed_pairs(RawArray<uint64_t>& records, int key_bits);

/// Serial stable LSD sort of n packed records (key and payload in one uint64_t) by bits
/// [first_bit, first_bit + key_bits), 8-bit digits: 256 scatter streams stay within the TLB
/// and, for up to ~10^5 records, the caches (the stream mode's sort). `tmp` holds n records;
/// returns the array that holds the result (records or tmp).
uint64_t* radix_sort_packed(uint64_t* records, uint64_t* tmp, size_t n, int first_bit,
                            int key_bits);
/// The same sort on the thread pool (per pass: each fixed chunk's digit counts, then each
/// chunk's scatter), for large batches; the same result as radix_sort_packed.
uint64_t* radix_sort_packed_parallel(uint64_t* records, uint64_t* tmp, size_t n, int first_bit,
                                     int key_bits);

}  // namespace kestrel
