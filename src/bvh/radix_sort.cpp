#include "bvh/radix_sort.h"

#include <algorithm>
#include <vector>

#include "core/parallel.h"

namespace kestrel {

namespace {

constexpr int digit_bits = 11;
constexpr size_t bucket_count = size_t(1) << digit_bits;
constexpr size_t sort_chunk = 1u << 16;

// Turns per-chunk digit counts into write offsets: an exclusive scan in (digit, chunk)
// order. Returns true when one digit holds every key (the pass would move nothing).
bool scan_offsets(std::vector<uint32_t>& hist, size_t chunks, size_t n) {
  for (size_t d = 0; d < bucket_count; ++d) {
    uint32_t total = 0;
    for (size_t c = 0; c < chunks; ++c) total += hist[c * bucket_count + d];
    if (total == n) return true;
    if (total != 0) break;
  }
  uint32_t running = 0;
  for (size_t d = 0; d < bucket_count; ++d)
    for (size_t c = 0; c < chunks; ++c) {
      const uint32_t v = hist[c * bucket_count + d];
      hist[c * bucket_count + d] = running;
      running += v;
    }
  return false;
}

template <class Key>
void radix_sort_impl(RawArray<Key>& keys, RawArray<uint32_t>& values, int key_bits) {
  const size_t n = keys.size();
  if (n < 2) return;
  RawArray<Key> keys_tmp(n);
  RawArray<uint32_t> values_tmp(n);
  const size_t chunks = chunk_count(n, sort_chunk);
  std::vector<uint32_t> hist(chunks * bucket_count);
  for (int shift = 0; shift < key_bits; shift += digit_bits) {
    std::fill(hist.begin(), hist.end(), 0u);
    parallel_for(0, chunks, 1, [&](size_t cb, size_t ce) {
      for (size_t c = cb; c < ce; ++c) {
        uint32_t* h = &hist[c * bucket_count];
        const size_t e = std::min(n, (c + 1) * sort_chunk);
        for (size_t i = c * sort_chunk; i < e; ++i) h[(keys[i] >> shift) & (bucket_count - 1)]++;
      }
    });
    if (scan_offsets(hist, chunks, n)) continue;
    parallel_for(0, chunks, 1, [&](size_t cb, size_t ce) {
      for (size_t c = cb; c < ce; ++c) {
        uint32_t* offset = &hist[c * bucket_count];
        const size_t e = std::min(n, (c + 1) * sort_chunk);
        for (size_t i = c * sort_chunk; i < e; ++i) {
          uint32_t o = offset[(keys[i] >> shift) & (bucket_count - 1)]++;
          keys_tmp[o] = keys[i];
          values_tmp[o] = values[i];
        }
      }
    });
    keys.swap(keys_tmp);
    values.swap(values_tmp);
  }
}

// LSD radix sort of 64-bit words on bits [first_bit, first_bit + key_bits).
// Serial: the counts of every digit are gathered in one pass over the words (the keys do
// not change between passes, only their order), then each pass is a single scatter.
// Parallel: per pass, per-chunk counts of the current order, then a parallel scatter.
// Both are stable sorts, so they give the same order.
void radix_sort_packed(RawArray<uint64_t>& words, int first_bit, int key_bits) {
  const size_t n = words.size();
  if (n < 2) return;
  const int digits = (key_bits + digit_bits - 1) / digit_bits;
  RawArray<uint64_t> tmp(n);
  const size_t chunks = chunk_count(n, sort_chunk);
  if (current_thread_count() == 1 || chunks == 1) {
    std::vector<uint32_t> hist(size_t(digits) * bucket_count, 0u);
    for (size_t i = 0; i < n; ++i)
      for (int d = 0; d < digits; ++d) hist[d * bucket_count + ((words[i] >> (first_bit + d * digit_bits)) & (bucket_count - 1))]++;
    for (int d = 0; d < digits; ++d) {
      std::vector<uint32_t> offset(hist.begin() + d * bucket_count, hist.begin() + (d + 1) * bucket_count);
      if (scan_offsets(offset, 1, n)) continue;
      const int shift = first_bit + d * digit_bits;
      for (size_t i = 0; i < n; ++i) tmp[offset[(words[i] >> shift) & (bucket_count - 1)]++] = words[i];
      words.swap(tmp);
    }
    return;
  }
  std::vector<uint32_t> hist(chunks * bucket_count);
  for (int shift = first_bit; shift < first_bit + key_bits; shift += digit_bits) {
    std::fill(hist.begin(), hist.end(), 0u);
    parallel_for(0, chunks, 1, [&](size_t cb, size_t ce) {
      for (size_t c = cb; c < ce; ++c) {
        uint32_t* h = &hist[c * bucket_count];
        const size_t e = std::min(n, (c + 1) * sort_chunk);
        for (size_t i = c * sort_chunk; i < e; ++i) h[(words[i] >> shift) & (bucket_count - 1)]++;
      }
    });
    if (scan_offsets(hist, chunks, n)) continue;
    parallel_for(0, chunks, 1, [&](size_t cb, size_t ce) {
      for (size_t c = cb; c < ce; ++c) {
        uint32_t* offset = &hist[c * bucket_count];
        const size_t e = std::min(n, (c + 1) * sort_chunk);
        for (size_t i = c * sort_chunk; i < e; ++i) tmp[offset[(words[i] >> shift) & (bucket_count - 1)]++] = words[i];
      }
    });
    words.swap(tmp);
  }
}

}  // namespace

void radix_sort(RawArray<uint32_t>& keys, RawArray<uint32_t>& values, int key_bits) {
  // Packed as (key << 32 | value) and sorted on the high half: one 8-byte scatter per
  // element and pass instead of two 4-byte ones into separate arrays.
  const size_t n = keys.size();
  RawArray<uint64_t> packed(n);
  parallel_for(0, n, 65536, [&](size_t b, size_t e) {
    for (size_t i = b; i < e; ++i) packed[i] = uint64_t(keys[i]) << 32 | values[i];
  });
  radix_sort_packed(packed, 32, key_bits);
  parallel_for(0, n, 65536, [&](size_t b, size_t e) {
    for (size_t i = b; i < e; ++i) {
      keys[i] = uint32_t(packed[i] >> 32);
      values[i] = uint32_t(packed[i]);
    }
  });
}
void radix_sort(RawArray<uint64_t>& keys, RawArray<uint32_t>& values, int key_bits) {
  radix_sort_impl(keys, values, key_bits);
}

}  // namespace kestrel
