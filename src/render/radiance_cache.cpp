#include "render/radiance_cache.h"

#include <algorithm>
#include <bit>
#include <cmath>

#include "render/sampling.h"

namespace kestrel::render {

namespace {

// The exponent e of the power-of-two cell edge 2^e in (x, 2x] (x > 0), within the float range:
// frexp's (x = m * 2^e, m in [0.5, 1)) read off the bits of a normal x. (frexp and ldexp were
// libm calls in cell(), which runs once per first-bounce hit.)
int cell_exponent(float x) {
  if (!(x > 0x1p-120f)) return -120;
  if (!(x < 0x1p120f)) return 120;
  return int((std::bit_cast<uint32_t>(x) >> 23) & 0xFFu) - 126;
}

// 2^e for |e| <= 120, exactly.
double pow2(int e) {
  return std::bit_cast<double>(uint64_t(1023 + e) << 52);
}
float pow2f(int e) {
  return std::bit_cast<float>(uint32_t(127 + e) << 23);
}

// floor(p * inv_cell) clamped to +-2^62: clamped first (the bounds are integers, so the same
// value), then floored through the integer conversion (no rounding instruction in baseline
// x86-64).
int64_t cell_coordinate(float p, double inv_cell) {
  const double c = std::clamp(double(p) * inv_cell, -0x1p62, 0x1p62);
  const int64_t i = int64_t(c);
  return double(i) > c ? i - 1 : i;
}

}  // namespace

RadianceCache::Cell RadianceCache::cell(Vec3 p, Vec3 ng) const {
  const int e = cell_exponent(length(p - eye_) * pixel_angle_ * cell_pixels);
  const double inv = pow2(-e);
  const float ax = std::fabs(ng.x), ay = std::fabs(ng.y), az = std::fabs(ng.z);
  const int axis = ax >= ay ? (ax >= az ? 0 : 2) : (ay >= az ? 1 : 2);
  const uint64_t face = uint64_t(2 * axis + (ng[axis] < 0 ? 1 : 0));
  uint64_t h = mix64(uint64_t(e + 256) | face << 16);
  h = mix64(h ^ uint64_t(cell_coordinate(p.x, inv)));
  h = mix64(h ^ uint64_t(cell_coordinate(p.y, inv)) * 0x9E3779B97F4A7C15ull);
  h = mix64(h ^ uint64_t(cell_coordinate(p.z, inv)) * 0xC2B2AE3D27D4EB4Full);
  return {h | 1, pow2f(e)};  // never the empty key
}

size_t RadianceCache::find(uint64_t key) const {
  if (cells_.empty()) return capacity;
  for (size_t i = key & (capacity - 1), n = 0; n < capacity; ++n, i = (i + 1) & (capacity - 1)) {
    if (cells_[i].key == key) return i;
    if (cells_[i].key == 0) return capacity;
  }
  return capacity;
}

bool RadianceCache::lookup(uint64_t key, Vec3& radiance) const {
  const size_t i = find(key);
  if (i == capacity || cells_[i].samples < min_samples) return false;
  radiance = cells_[i].mean;
  return true;
}

size_t RadianceCache::insert(uint64_t key) {
  if (cells_.empty()) cells_.resize(capacity), pending_.resize(capacity);
  // Keep the table at most half full: probes stay short; new cells wait for an eviction.
  for (size_t i = key & (capacity - 1);; i = (i + 1) & (capacity - 1)) {
    if (cells_[i].key == key) return i;
    if (cells_[i].key == 0) {
      if (2 * live_ >= capacity) return capacity;
      cells_[i].key = key;
      cells_[i].last = pass_;
      ++live_;
      return i;
    }
  }
}

void RadianceCache::add(std::span<const CacheRecord> records) {
  for (const CacheRecord& r : records) {
    const size_t i = insert(r.key);
    if (i == capacity) continue;
    Pending& p = pending_[i];
    if (p.count == 0) touched_.push_back(uint32_t(i));
    p.sum = p.sum + r.radiance;
    ++p.count;
  }
}

void RadianceCache::end_pass() {
  for (const uint32_t i : touched_) {
    Slot& c = cells_[i];
    Pending& p = pending_[i];
    // The history's weight halves every half_life passes (and is capped): lighting that
    // changes reaches the cells within a few half-lives however few samples they get.
    const float n = float(p.count),
                aged = c.samples * std::exp2(-float(pass_ - c.last) / float(half_life));
    const float keep = std::max(std::min(aged, max_samples - n), 0.0f);
    c.mean = (c.mean * keep + p.sum) * (1.0f / (keep + n));
    c.samples = keep + n;
    c.last = pass_;
    p = Pending{};
  }
  touched_.clear();
  ++pass_;
  if (pass_ % 16 == 0 || live_ >= evict_at) evict();
}

void RadianceCache::evict() {
  if (cells_.empty()) return;
  // The oldest age kept: max_age, or less when that would keep more than keep_at cells
  // (ages 0 .. limit are kept; the cells sampled this pass at least).
  uint32_t limit = max_age;
  if (live_ >= evict_at) {
    size_t count[max_age + 2] = {};
    for (const Slot& c : cells_)
      if (c.key != 0) ++count[std::min(pass_ - c.last, max_age + 1)];
    size_t kept = count[0];
    limit = 0;
    while (limit < max_age && kept + count[limit + 1] <= keep_at) kept += count[++limit];
  }
  if (spare_.size() != capacity)
    spare_.assign(capacity, Slot{});
  else
    std::fill(spare_.begin(), spare_.end(), Slot{});
  live_ = 0;
  for (const Slot& c : cells_) {
    if (c.key == 0 || pass_ - c.last > limit) continue;
    size_t i = c.key & (capacity - 1);
    while (spare_[i].key != 0) i = (i + 1) & (capacity - 1);
    spare_[i] = c;
    ++live_;
  }
  cells_.swap(spare_);
}

void RadianceCache::clear() {
  cells_.clear();
  cells_.shrink_to_fit();
  spare_.clear();
  spare_.shrink_to_fit();
  pending_.clear();
  pending_.shrink_to_fit();
  touched_.clear();
  live_ = 0;
  pass_ = 0;
}

}  // namespace kestrel::render
