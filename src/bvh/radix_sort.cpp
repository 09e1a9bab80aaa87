#include "bvh/radix_sort.h"

#include <algorithm>
#include <array>
#include <vector>

#include "core/parallel.h"

namespace kestrel {

namespace {

constexpr int digit_bits = 11;
constexpr size_t bucket_count = size_t(1) << digit_bits;
constexpr size_t sort_chunk = 1u << 16;

// Turns per-chunk digit counts (`buckets` per chunk) into write offsets: an exclusive scan in
// (digit, chunk) order. Returns true when one digit holds every key (the pass would move
// nothing).
bool scan_offsets(std::vector<uint32_t>& hist, size_t chunks, size_t n,
                  size_t buckets = bucket_count) {
  for (size_t d = 0; d < buckets; ++d) {
    uint32_t total = 0;
    for (size_t c = 0; c < chunks; ++c) total += hist[c * buckets + d];
    if (total == n) return true;
    if (total != 0) break;
  }
  uint32_t running = 0;
  for (size_t d = 0; d < buckets; ++d)
    for (size_t c = 0; c < chunks; ++c) {
      const uint32_t v = hist[c * buckets + d];
      hist[c * buckets + d] = running;
      running += v;
    }
  return false;
}

// One stable LSD pass on the thread pool over fixed chunks of `chunk` records: each chunk's
// counts of the digit (Bits wide) at `shift`, the (digit, chunk) scan, then each chunk's
// scatter from src to dst. Returns false (nothing moved) when one digit holds every record.
template <int Bits, class Record, class KeyOf>
bool parallel_pass(const Record* src, Record* dst, size_t n, size_t chunk, int shift,
                   std::vector<uint32_t>& hist, KeyOf key_of) {
  constexpr size_t buckets = size_t(1) << Bits;
  const size_t chunks = chunk_count(n, chunk);
  hist.assign(chunks * buckets, 0u);
  auto digit = [&](const Record& r) { return size_t(key_of(r) >> shift) & (buckets - 1); };
  parallel_for(0, chunks, 1, [&](size_t cb, size_t ce) {
    for (size_t c = cb; c < ce; ++c) {
      uint32_t* h = &hist[c * buckets];
      for (size_t i = c * chunk, e = std::min(n, i + chunk); i < e; ++i) h[digit(src[i])]++;
    }
  });
  if (scan_offsets(hist, chunks, n, buckets)) return false;
  parallel_for(0, chunks, 1, [&](size_t cb, size_t ce) {
    for (size_t c = cb; c < ce; ++c) {
      uint32_t* offset = &hist[c * buckets];
      for (size_t i = c * chunk, e = std::min(n, i + chunk); i < e; ++i)
        dst[offset[digit(src[i])]++] = src[i];
    }
  });
  return true;
}

// LSD radix sort of records on the key bits [first_bit, first_bit + key_bits) that
// key_of(record) returns. Serial: the counts of every digit are gathered in one pass (the
// keys do not change between passes, only their order), then each pass is one scatter.
// Parallel: per pass, per-chunk counts of the current order, then a parallel scatter.
// Both are stable sorts, so they give the same order.
template <class Record, class KeyOf>
void lsd_sort(RawArray<Record>& records, int first_bit, int key_bits, KeyOf key_of) {
  const size_t n = records.size();
  if (n < 2) return;
  const int digits = (key_bits + digit_bits - 1) / digit_bits;
  auto digit = [&](const Record& r, int shift) {
    return size_t(key_of(r) >> shift) & (bucket_count - 1);
  };
  RawArray<Record> tmp(n);
  const size_t chunks = chunk_count(n, sort_chunk);
  if (current_thread_count() == 1 || chunks == 1) {
    std::vector<uint32_t> hist(size_t(digits) * bucket_count, 0u);
    for (size_t i = 0; i < n; ++i)
      for (int d = 0; d < digits; ++d)
        hist[d * bucket_count + digit(records[i], first_bit + d * digit_bits)]++;
    for (int d = 0; d < digits; ++d) {
      std::vector<uint32_t> offset(hist.begin() + d * bucket_count,
                                   hist.begin() + (d + 1) * bucket_count);
      if (scan_offsets(offset, 1, n)) continue;
      const int shift = first_bit + d * digit_bits;
      for (size_t i = 0; i < n; ++i) tmp[offset[digit(records[i], shift)]++] = records[i];
      records.swap(tmp);
    }
    return;
  }
  std::vector<uint32_t> hist;
  for (int shift = first_bit; shift < first_bit + key_bits; shift += digit_bits)
    if (parallel_pass<digit_bits>(records.data(), tmp.data(), n, sort_chunk, shift, hist, key_of))
      records.swap(tmp);
}

// Sorts (key, value) pairs through records that carry both, so each pass moves one record.
template <class Record, class Key>
void sort_pairs(RawArray<Key>& keys, RawArray<uint32_t>& values, int first_bit, int key_bits,
                Record (*pack)(Key, uint32_t), void (*unpack)(const Record&, Key&, uint32_t&),
                uint64_t (*key_of)(const Record&)) {
  const size_t n = keys.size();
  RawArray<Record> records(n);
  parallel_for(0, n, 65536, [&](size_t b, size_t e) {
    for (size_t i = b; i < e; ++i) records[i] = pack(keys[i], values[i]);
  });
  lsd_sort(records, first_bit, key_bits, key_of);
  parallel_for(0, n, 65536, [&](size_t b, size_t e) {
    for (size_t i = b; i < e; ++i) unpack(records[i], keys[i], values[i]);
  });
}

struct KeyValue64 {
  uint64_t key;
  uint32_t value;
};

}  // namespace

void radix_sort_packed_pairs(RawArray<uint64_t>& records, int key_bits) {
  lsd_sort(records, 32, key_bits, [](const uint64_t& r) { return r; });
}

void radix_sort(RawArray<uint64_t>& keys, RawArray<uint32_t>& values, int key_bits) {
  sort_pairs<KeyValue64, uint64_t>(
      keys, values, 0, key_bits,
      [](uint64_t k, uint32_t v) {
        return KeyValue64{k, v};
      },
      [](const KeyValue64& r, uint64_t& k, uint32_t& v) {
        k = r.key;
        v = r.value;
      },
      [](const KeyValue64& r) { return r.key; });
}

uint64_t* radix_sort_packed(uint64_t* a, uint64_t* b, size_t n, int first_bit, int key_bits) {
  const int passes = (key_bits + 7) / 8;
  std::vector<std::array<uint32_t, 256>> start(static_cast<size_t>(passes));
  for (auto& s : start) s.fill(0);
  for (size_t i = 0; i < n; ++i)  // every digit's counts in one read
    for (int p = 0; p < passes; ++p) ++start[p][(a[i] >> (first_bit + 8 * p)) & 0xFF];
  for (int p = 0; p < passes; ++p) {
    uint32_t sum = 0;
    bool one_digit = false;
    for (uint32_t& s : start[p]) {
      const uint32_t c = s;
      one_digit |= c == n;
      s = sum;
      sum += c;
    }
    if (one_digit) continue;  // every record has the same digit: the pass would move nothing
    const int shift = first_bit + 8 * p;
    for (size_t i = 0; i < n; ++i) b[start[p][(a[i] >> shift) & 0xFF]++] = a[i];
    std::swap(a, b);
  }
  return a;
}

uint64_t* radix_sort_packed_parallel(uint64_t* a, uint64_t* b, size_t n, int first_bit,
                                     int key_bits) {
  constexpr size_t chunk = size_t(1) << 15;
  if (current_thread_count() == 1 || chunk_count(n, chunk) == 1)
    return radix_sort_packed(a, b, n, first_bit, key_bits);
  std::vector<uint32_t> hist;
  for (int shift = first_bit; shift < first_bit + key_bits; shift += 8)
    if (parallel_pass<8>(a, b, n, chunk, shift, hist, [](uint64_t r) { return r; }))
      std::swap(a, b);
  return a;
}

}  // namespace kestrel
