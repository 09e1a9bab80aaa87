// The binned SAH builder's parts (binned_sah_builder.cpp): range bounds, bins, the map from
// centroids to bins, and the side accumulators of its branch-free partitions.
#pragma once
#include <cstddef>
#include <cstdint>
#include <limits>

#include "core/simd/vec4f.h"

namespace kestrel::binned {

using simd::Vec4f;

constexpr int max_bins = 32;

/// The doubled centroid lo + hi, lane 3 zero (lo's lane 3 is the prim id: simd::clear_w).
inline Vec4f centroid2(Vec4f lo, Vec4f hi) {
  return simd::clear_w(lo) + hi;
}

/// Bounds of a range: geometric, and of the doubled centroids (lo + hi).
struct RangeInfo {
  Vec4f geom_lo, geom_hi, cent_lo, cent_hi;
  size_t begin, end;
  static RangeInfo empty_at(size_t begin) {
    return {Vec4f(std::numeric_limits<float>::infinity()),
            Vec4f(-std::numeric_limits<float>::infinity()),
            Vec4f(std::numeric_limits<float>::infinity()),
            Vec4f(-std::numeric_limits<float>::infinity()),
            begin,
            begin};
  }
  void add(Vec4f lo, Vec4f hi) {
    geom_lo = min(geom_lo, lo);
    geom_hi = max(geom_hi, hi);
    const Vec4f c = centroid2(lo, hi);
    cent_lo = min(cent_lo, c);
    cent_hi = max(cent_hi, c);
  }
};

struct Bins {
  Vec4f lo[3][max_bins], hi[3][max_bins];
  uint32_t count[3][max_bins];
  void clear(int bin_count) {
    for (int a = 0; a < 3; ++a)
      for (int b = 0; b < bin_count; ++b) {
        lo[a][b] = Vec4f(std::numeric_limits<float>::infinity());
        hi[a][b] = Vec4f(-std::numeric_limits<float>::infinity());
        count[a][b] = 0;
      }
  }
  /// Adds a reference with bounds [lo, hi] to its bin on each axis.
  void add(const int* bin, Vec4f lo, Vec4f hi) {
    for (int a = 0; a < 3; ++a) {
      this->lo[a][bin[a]] = min(this->lo[a][bin[a]], lo);
      this->hi[a][bin[a]] = max(this->hi[a][bin[a]], hi);
      count[a][bin[a]]++;
    }
  }
  void merge(const Bins& o, int bin_count) {
    for (int a = 0; a < 3; ++a)
      for (int b = 0; b < bin_count; ++b) {
        lo[a][b] = min(lo[a][b], o.lo[a][b]);
        hi[a][b] = max(hi[a][b], o.hi[a][b]);
        count[a][b] += o.count[a][b];
      }
  }
};

struct BinMapping {
  Vec4f offset, scale;
  int bin_count;
  BinMapping(const RangeInfo& info, int bins) : offset(info.cent_lo), bin_count(bins) {
    // Slightly under bins/extent so the largest centroid lands in the last bin, not past it.
    Vec4f ext = info.cent_hi - info.cent_lo;
    alignas(16) float e[4], s[4];
    ext.store(e);
    for (int a = 0; a < 3; ++a) s[a] = e[a] > 0.0f ? float(bins) * 0.99999f / e[a] : 0.0f;
    s[3] = 0.0f;
    scale = Vec4f::load(s);
    offset = simd::clear_w(offset);
    top = Vec4f(float(bins - 1));
  }
  // Clamped in float before truncation: two SIMD ops instead of three integer clamps.
  // The partition calls the same function, so a reference always lands in the bin it was
  // counted in (a mismatch could leave one side empty).
  void bin_of(Vec4f lo, Vec4f hi, int* out) const {
    simd::to_int(min(max((centroid2(lo, hi) - offset) * scale, Vec4f(0.0f)), top), out);
  }
  Vec4f top = Vec4f(0.0f);
};

// Side accumulators of a branch-free partition: a reference's box joins one side's bounds
// through a lane mask instead of a branch (the side is as unpredictable as a coin). A box
// that does not join is made NaN (all bits set), which MINPS / MAXPS pass over: they return
// their second operand, the accumulator, when the first is NaN.
struct SideBounds {
  Vec4f geom_lo = Vec4f(std::numeric_limits<float>::infinity()),
        geom_hi = Vec4f(-std::numeric_limits<float>::infinity()),
        cent_lo = Vec4f(std::numeric_limits<float>::infinity()),
        cent_hi = Vec4f(-std::numeric_limits<float>::infinity());
  // Adds [lo, hi] unless skip is all ones; c is their doubled centroid (centroid2).
  void add_unless(__m128 skip, Vec4f lo, Vec4f hi, Vec4f c) {
    const __m128 l = _mm_or_ps(lo.v, skip), h = _mm_or_ps(hi.v, skip), cc = _mm_or_ps(c.v, skip);
    geom_lo = Vec4f(_mm_min_ps(l, geom_lo.v));
    geom_hi = Vec4f(_mm_max_ps(h, geom_hi.v));
    cent_lo = Vec4f(_mm_min_ps(cc, cent_lo.v));
    cent_hi = Vec4f(_mm_max_ps(cc, cent_hi.v));
  }
  RangeInfo range(size_t begin, size_t end) const {
    return {geom_lo, geom_hi, cent_lo, cent_hi, begin, end};
  }
};

inline __m128 lane_mask(bool b) {
  return _mm_castsi128_ps(_mm_set1_epi32(-int32_t(b)));
}

}  // namespace kestrel::binned
