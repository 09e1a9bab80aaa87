#include "bvh/radix_sort.h"

#include <algorithm>

#include "core/parallel.h"

namespace kestrel {

namespace {

constexpr int digit_bits = 11;
constexpr size_t bucket_count = size_t(1) << digit_bits;
constexpr size_t sort_chunk = 1u << 16;

template <class Key>
void radix_sort_impl(std::vector<Key>& keys, std::vector<uint32_t>& values, int key_bits) {
  const size_t n = keys.size();
  if (n < 2) return;
  std::vector<Key> keys_tmp(n);
  std::vector<uint32_t> values_tmp(n);
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
    // A digit every key shares moves nothing: skip the pass.
    bool trivial = false;
    for (size_t d = 0; d < bucket_count; ++d) {
      uint32_t total = 0;
      for (size_t c = 0; c < chunks; ++c) total += hist[c * bucket_count + d];
      if (total == n) trivial = true;
      if (total != 0) break;
    }
    if (trivial) continue;
    // Exclusive scan in (digit, chunk) order gives each chunk its write offsets per digit.
    uint32_t running = 0;
    for (size_t d = 0; d < bucket_count; ++d)
      for (size_t c = 0; c < chunks; ++c) {
        uint32_t v = hist[c * bucket_count + d];
        hist[c * bucket_count + d] = running;
        running += v;
      }
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

}  // namespace

void radix_sort(std::vector<uint32_t>& keys, std::vector<uint32_t>& values, int key_bits) {
  radix_sort_impl(keys, values, key_bits);
}
void radix_sort(std::vector<uint64_t>& keys, std::vector<uint32_t>& values, int key_bits) {
  radix_sort_impl(keys, values, key_bits);
}

}  // namespace kestrel
