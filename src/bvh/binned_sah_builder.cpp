// Binned SAH (Wald 2007, "On fast construction of SAH-based bounding volume hierarchies").
//
// Centroids are binned on all three axes at once (up to 32 bins), the bins are swept from
// both ends, and the references are partitioned in place. Each node carries its geometric
// and centroid bounds from its parent's partition pass, so no extra pass over the range is
// needed. Large ranges are binned in parallel over fixed chunks (merged in chunk order, so
// results do not depend on the thread count); subtrees are built in parallel through
// core/parallel.h with node slots fixed in advance (node_slots.h), each reporting its node
// count so the slots compact in parallel too.
#include <algorithm>
#include <atomic>
#include <cstring>
#include <limits>
#include <vector>

#include "bvh/binned_parts.h"
#include "bvh/builders.h"
#include "bvh/node_slots.h"
#include "bvh/radix_sort.h"
#include "bvh/sah.h"
#include "core/parallel.h"
#include "core/raw_array.h"
#include "core/simd/vec4f.h"
#include "core/vec.h"

namespace kestrel {

namespace {

using namespace binned;  // Vec4f, RangeInfo, Bins, BinMapping, SideBounds

// Ranges this small are split by an exact sweep over centroid-sorted primitives instead of
// bins: cheaper than clearing and sweeping 3 x bin_count bins, and never worse in SAH.
constexpr size_t exact_sweep_max = 8;
// Small inputs (a whole build of at most small_input references takes microseconds) use the
// exact sweep up to exact_sweep_cap references: with few, large primitives, coarse bins
// choose visibly worse splits.
constexpr size_t small_input = 4096;
constexpr size_t exact_sweep_cap = 64;
// Ranges at least this large get their binned split refined exactly (refine_and_partition);
// below it the sort would cost more than it gains over the plain binned split.
constexpr size_t refine_min = 256;
// Middles of at least this many references are sorted by radix (std::sort below).
constexpr size_t radix_min = 64;
// Ranges at least this large are binned into two alternating bin sets (see bin_range).
constexpr size_t two_set_min = 256;
// Ranges at least this large are binned in parallel chunks of binning_chunk.
constexpr size_t parallel_binning_threshold = 1u << 16;
constexpr size_t binning_chunk = 1u << 14;

// The references are partitioned out of place: a range lives in one of two buffers and its
// children in the other (each node records which), so a partition is one branch-free pass
// that writes every reference once. Leaves write their prim ids into `ids` (leaf order).
struct BinnedBuilder {
  const BuildConfig& config;
  NodeSlots& slots;
  uint32_t* ids;
  int bin_count;
  size_t exact_max;   // exact sweep for ranges up to this size
  size_t block_leaf;  // ranges up to this size are leaves (0: none; see build_binned_sah)

  static Vec4f ref_lo(const PrimRef* r, size_t i) { return Vec4f::load(&r[i].lo); }
  static Vec4f ref_hi(const PrimRef* r, size_t i) { return Vec4f::load(&r[i].hi); }

  // Alternate references go to two bin sets, merged at the end: runs of neighbouring
  // references fall in the same bin, and one set would serialise on its read-modify-writes.
  void bin_range(const BinMapping& map, const PrimRef* r, size_t begin, size_t end,
                 Bins& bins) const {
    bins.clear(map.bin_count);
    int b0[4], b1[4];
    size_t i = begin;
    if (end - begin < two_set_min) {  // small ranges: clearing and merging a second set costs more
      for (; i < end; ++i) {
        const Vec4f lo = ref_lo(r, i), hi = ref_hi(r, i);
        map.bin_of(lo, hi, b0);
        bins.add(b0, lo, hi);
      }
      return;
    }
    Bins odd;
    odd.clear(map.bin_count);
    for (; i + 1 < end; i += 2) {
      const Vec4f lo0 = ref_lo(r, i), hi0 = ref_hi(r, i), lo1 = ref_lo(r, i + 1),
                  hi1 = ref_hi(r, i + 1);
      map.bin_of(lo0, hi0, b0);
      map.bin_of(lo1, hi1, b1);
      bins.add(b0, lo0, hi0);
      odd.add(b1, lo1, hi1);
    }
    if (i < end) {
      const Vec4f lo = ref_lo(r, i), hi = ref_hi(r, i);
      map.bin_of(lo, hi, b0);
      bins.add(b0, lo, hi);
    }
    bins.merge(odd, map.bin_count);
  }

  void bin(const BinMapping& map, const RangeInfo& info, const PrimRef* r, Bins& bins) const {
    const size_t n = info.end - info.begin;
    if (n < parallel_binning_threshold) return bin_range(map, r, info.begin, info.end, bins);
    const size_t chunks = chunk_count(n, binning_chunk);
    std::vector<Bins> partial(chunks);
    parallel_for(0, chunks, 1, [&](size_t cb, size_t ce) {
      for (size_t c = cb; c < ce; ++c)
        bin_range(map, r, info.begin + c * binning_chunk,
                  std::min(info.end, info.begin + (c + 1) * binning_chunk), partial[c]);
    });
    bins = partial[0];
    for (size_t c = 1; c < chunks; ++c) bins.merge(partial[c], map.bin_count);
  }

  uint32_t make_leaf(uint32_t slot, const RangeInfo& info, const PrimRef* r) {
    for (size_t i = info.begin; i < info.end; ++i) ids[i] = r[i].prim_id;
    Bvh2Node& node = slots[slot];
    alignas(16) float lo[4], hi[4];
    info.geom_lo.store(lo);
    info.geom_hi.store(hi);
    node = Bvh2Node{{lo[0], lo[1], lo[2]},
                    uint32_t(info.begin),
                    {hi[0], hi[1], hi[2]},
                    uint32_t(info.end - info.begin)};
    return 1;
  }

  // Splits [begin, end) at its middle (all centroids equal: no SAH split exists).
  static void split_middle(const RangeInfo& info, const PrimRef* r, RangeInfo& left,
                           RangeInfo& right) {
    size_t mid = info.begin + (info.end - info.begin) / 2;
    left = RangeInfo::empty_at(info.begin);
    right = RangeInfo::empty_at(mid);
    for (size_t i = info.begin; i < mid; ++i) left.add(ref_lo(r, i), ref_hi(r, i));
    for (size_t i = mid; i < info.end; ++i) right.add(ref_lo(r, i), ref_hi(r, i));
    left.end = mid;
    right.end = info.end;
  }

  // Builds slot `slot` over `info`, whose references are in r[info.begin, info.end); `spare`
  // is the other buffer. The children's references end up in r or in spare (`data`). Returns
  // the subtree's node count.
  uint32_t build(uint32_t slot, uint32_t pair, const RangeInfo& info, PrimRef* r, PrimRef* spare) {
    const size_t n = info.end - info.begin;
    if (n == 1 || n <= block_leaf) return make_leaf(slot, info, r);
    PrimRef* data = r;  // where the range's references are now
    PrimRef* other = spare;
    const float node_area = simd::half_area(info.geom_lo, info.geom_hi);
    const float inv_area = inverse_area(node_area);
    RangeInfo left, right;
    alignas(16) float cext[4];
    (info.cent_hi - info.cent_lo).store(cext);
    if (cext[0] <= 0.0f && cext[1] <= 0.0f && cext[2] <= 0.0f) {
      if (n <= config.max_leaf_size) return make_leaf(slot, info, r);
      split_middle(info, r, left, right);
    } else if (n <= exact_max) {
      if (!exact_split(info, r, inv_area, left, right)) return make_leaf(slot, info, r);
    } else {
      // Bins scale with the range: the top levels (few nodes, many references) get the full
      // count -- coarse bins there cut through clustered objects -- while small nodes, where
      // the per-bin sweep would dominate, get fewer.
      const int bins_here = std::clamp(int(n / 4), 8, bin_count);
      const BinMapping map(info, bins_here);
      Bins bins;
      bin(map, info, r, bins);
      // Sweep: right-to-left suffix areas, then left-to-right costs.
      float best_cost = std::numeric_limits<float>::infinity();
      int best_axis = -1, best_split = 0;
      for (int a = 0; a < 3; ++a) {
        if (cext[a] <= 0.0f) continue;
        float right_area[max_bins];
        uint32_t right_count[max_bins];
        Vec4f lo(std::numeric_limits<float>::infinity()),
            hi(-std::numeric_limits<float>::infinity());
        uint32_t count = 0;
        for (int b = map.bin_count - 1; b > 0; --b) {
          lo = min(lo, bins.lo[a][b]);
          hi = max(hi, bins.hi[a][b]);
          count += bins.count[a][b];
          right_area[b] = simd::half_area(lo, hi);
          right_count[b] = count;
        }
        lo = Vec4f(std::numeric_limits<float>::infinity());
        hi = Vec4f(-std::numeric_limits<float>::infinity());
        count = 0;
        for (int b = 0; b < map.bin_count - 1; ++b) {
          lo = min(lo, bins.lo[a][b]);
          hi = max(hi, bins.hi[a][b]);
          count += bins.count[a][b];
          if (count == 0 || right_count[b + 1] == 0) continue;
          float c = split_cost(config, inv_area, simd::half_area(lo, hi), count, right_area[b + 1],
                               right_count[b + 1]);
          if (c < best_cost) {
            best_cost = c;
            best_axis = a;
            best_split = b + 1;
          }
        }
      }
      if (best_axis >= 0) {
        if (n >= refine_min) {
          best_cost = refine_and_partition(best_axis, best_split, map, inv_area, info, r, spare,
                                           left, right);
        } else {
          partition(map, best_axis, best_split, info, r, spare, left, right);
        }
        std::swap(data, other);
      }
      // A leaf is weighed against the refined split (refinement only reorders the range).
      if (n <= config.max_leaf_size && leaf_cost(config, n) <= best_cost)
        return make_leaf(slot, info, data);
      if (best_axis < 0) split_middle(info, data, left, right);
    }
    // A split that separates nothing (every cost NaN: areas overflow float in scenes wider
    // than ~1e19, and the sweeps then keep an empty side) would recurse forever: halves.
    if (left.end == left.begin || right.end == right.begin) split_middle(info, data, left, right);
    slots[slot] = Bvh2Node{{}, pair, {}, 0};
    alignas(16) float lo[4], hi[4];
    info.geom_lo.store(lo);
    info.geom_hi.store(hi);
    slots[slot].lo = {lo[0], lo[1], lo[2]};
    slots[slot].hi = {hi[0], hi[1], hi[2]};
    const size_t left_count = left.end - left.begin;
    uint32_t left_nodes = 0, right_nodes = 0;
    build_children(
        n > config.parallel_threshold,
        [&] { left_nodes = build(pair, pair + 2, left, data, other); },
        [&] {
          right_nodes = build(pair + 1, right_descendants(pair, left_count), right, data, other);
        });
    return slots.set_subtree_nodes(slot, left_nodes, right_nodes);
  }

  // Exact SAH over the sorted centroids of a small range; false when a leaf is cheaper. The
  // three axes are swept at once: lane a of every vector below belongs to axis a. Each
  // reference's place in a stable sort by doubled centroid is counted (no branches), the
  // references are transposed into that order per axis, and the sweeps compute the same
  // float operations, in the same order, as a sweep per axis would.
  bool exact_split(const RangeInfo& info, PrimRef* refs, float inv_area, RangeInfo& left,
                   RangeInfo& right) const {
    const size_t n = info.end - info.begin;
    const PrimRef* r = refs + info.begin;
    __m128 key[exact_sweep_cap];
    for (size_t i = 0; i < n; ++i) key[i] = centroid2(ref_lo(r, i), ref_hi(r, i)).v;
    uint8_t order[3][exact_sweep_cap];
    for (size_t i = 0; i < n; ++i) {
      // Stable: i goes after the earlier references with keys <= its own.
      __m128i rank = _mm_setzero_si128();
      for (size_t j = 0; j < i; ++j)
        rank = _mm_sub_epi32(rank, _mm_castps_si128(_mm_cmple_ps(key[j], key[i])));
      for (size_t j = i + 1; j < n; ++j)
        rank = _mm_sub_epi32(rank, _mm_castps_si128(_mm_cmplt_ps(key[j], key[i])));
      alignas(16) int32_t k[4];
      _mm_store_si128(reinterpret_cast<__m128i*>(k), rank);
      for (int a = 0; a < 3; ++a) order[a][k[a]] = uint8_t(i);
    }
    // Position q's references on the three axes, as x, y and z rows of lo and hi.
    struct Rows {
      __m128 lx, ly, lz, hx, hy, hz;
    };
    Rows rows[exact_sweep_cap];
    for (size_t q = 0; q < n; ++q) {
      __m128 l0 = ref_lo(r, order[0][q]).v, l1 = ref_lo(r, order[1][q]).v,
             l2 = ref_lo(r, order[2][q]).v, l3 = _mm_setzero_ps();
      __m128 h0 = ref_hi(r, order[0][q]).v, h1 = ref_hi(r, order[1][q]).v,
             h2 = ref_hi(r, order[2][q]).v, h3 = _mm_setzero_ps();
      _MM_TRANSPOSE4_PS(l0, l1, l2, l3);
      _MM_TRANSPOSE4_PS(h0, h1, h2, h3);
      rows[q] = {l0, l1, l2, h0, h1, h2};
    }
    // simd::half_area per lane: (dx*dy + dy*dz) + dz*dx, with d = max(hi - lo, 0).
    const __m128 zero = _mm_setzero_ps();
    auto area = [zero](const Rows& b) {
      const __m128 dx = _mm_max_ps(_mm_sub_ps(b.hx, b.lx), zero),
                   dy = _mm_max_ps(_mm_sub_ps(b.hy, b.ly), zero),
                   dz = _mm_max_ps(_mm_sub_ps(b.hz, b.lz), zero);
      return _mm_add_ps(_mm_add_ps(_mm_mul_ps(dx, dy), _mm_mul_ps(dy, dz)), _mm_mul_ps(dz, dx));
    };
    auto grow = [](Rows& b, const Rows& o) {
      b = {_mm_min_ps(b.lx, o.lx), _mm_min_ps(b.ly, o.ly), _mm_min_ps(b.lz, o.lz),
           _mm_max_ps(b.hx, o.hx), _mm_max_ps(b.hy, o.hy), _mm_max_ps(b.hz, o.hz)};
    };
    const __m128 inf = _mm_set1_ps(std::numeric_limits<float>::infinity());
    const __m128 neg_inf = _mm_set1_ps(-std::numeric_limits<float>::infinity());
    const Rows empty{inf, inf, inf, neg_inf, neg_inf, neg_inf};
    __m128 right_area[exact_sweep_cap];
    Rows box = empty;
    for (size_t q = n; q-- > 1;) {
      grow(box, rows[q]);
      right_area[q] = area(box);
    }
    // split_cost per lane: Ct + (Ci * (Al * Nl + Ar * Nr)) * (1 / A); strict < keeps the
    // first minimum in position order.
    const __m128 ct = _mm_set1_ps(config.traversal_cost),
                 ci = _mm_set1_ps(config.intersection_cost), inv = _mm_set1_ps(inv_area);
    __m128 best = inf;
    __m128i best_q = _mm_setzero_si128();
    box = empty;
    for (size_t q = 0; q + 1 < n; ++q) {
      grow(box, rows[q]);
      const __m128 sum = _mm_add_ps(_mm_mul_ps(area(box), _mm_set1_ps(float(q + 1))),
                                    _mm_mul_ps(right_area[q + 1], _mm_set1_ps(float(n - q - 1))));
      const __m128 c = _mm_add_ps(ct, _mm_mul_ps(_mm_mul_ps(ci, sum), inv));
      const __m128 better = _mm_cmplt_ps(c, best);
      best = _mm_or_ps(_mm_and_ps(better, c), _mm_andnot_ps(better, best));
      best_q = _mm_or_si128(_mm_and_si128(_mm_castps_si128(better), _mm_set1_epi32(int(q + 1))),
                            _mm_andnot_si128(_mm_castps_si128(better), best_q));
    }
    alignas(16) float cost[4];
    alignas(16) int32_t split_at[4];
    _mm_store_ps(cost, best);
    _mm_store_si128(reinterpret_cast<__m128i*>(split_at), best_q);
    // The first minimum in (axis, position) order, as the sweeps per axis would find it.
    float best_cost = std::numeric_limits<float>::infinity();
    int best_axis = 0;
    size_t best_left = 0;
    for (int a = 0; a < 3; ++a)
      if (cost[a] < best_cost) {
        best_cost = cost[a];
        best_axis = a;
        best_left = size_t(split_at[a]);
      }
    if (n <= config.max_leaf_size && leaf_cost(config, n) <= best_cost) return false;
    PrimRef sorted[exact_sweep_cap];
    for (size_t i = 0; i < n; ++i) sorted[i] = r[order[best_axis][i]];
    left = RangeInfo::empty_at(info.begin);
    right = RangeInfo::empty_at(info.begin + best_left);
    for (size_t i = 0; i < n; ++i) {
      refs[info.begin + i] = sorted[i];
      (i < best_left ? left : right).add(Vec4f::load(&sorted[i].lo), Vec4f::load(&sorted[i].hi));
    }
    left.end = info.begin + best_left;
    right.end = info.end;
    return true;
  }

  // Position of a reference in bin units on `axis`: x = (c - offset) * scale, with c the
  // doubled centroid. Its bin is trunc(clamp(x)), so "bin < b" is exactly x < b -- computed
  // with the same float operations as in binning, so every reference lands on the side it
  // was counted on.
  static float position(const PrimRef& ref, int axis, const BinMapping& map) {
    return ((&ref.lo.x)[axis] + (&ref.hi.x)[axis] - map.offset[axis]) * map.scale[axis];
  }

  // Out of place: src[b, e) into dst[b, e), references with x < bound to the front (in
  // order), the rest to the back (in reverse order), with either side's bounds. Branch-free:
  // every reference is written once, to a slot chosen by a select. Returns the split point.
  static size_t scatter(const PrimRef* src, PrimRef* dst, size_t b, size_t e, int axis,
                        const BinMapping& map, float bound, SideBounds& front, SideBounds& back) {
    size_t f = b, k = e;  // dst[b, f) front, dst[k, e) back
    for (size_t i = b; i < e; ++i) {
      const Vec4f lo = ref_lo(src, i), hi = ref_hi(src, i);
      const bool left = position(src[i], axis, map) < bound;
      PrimRef* to = dst + (left ? f : k - 1);
      lo.store(&to->lo);
      hi.store(&to->hi);
      f += left;
      k -= !left;
      const __m128 to_back = lane_mask(!left);
      const Vec4f c = centroid2(lo, hi);
      front.add_unless(to_back, lo, hi, c);
      back.add_unless(_mm_xor_ps(to_back, lane_mask(true)), lo, hi, c);
    }
    return f;
  }

  // Partitions at a bin boundary, into `dst`: a reference goes left when its bin on `axis`
  // is below `split`.
  void partition(const BinMapping& map, int axis, int split, const RangeInfo& info,
                 const PrimRef* src, PrimRef* dst, RangeInfo& left, RangeInfo& right) const {
    SideBounds l, r;
    const size_t mid = scatter(src, dst, info.begin, info.end, axis, map, float(split), l, r);
    left = l.range(info.begin, mid);
    right = r.range(mid, info.end);
  }

  // Refines the chosen bin boundary while partitioning into `dst`. On regular structures
  // (grids, tessellated planes) bin boundaries cut through rows of centroids, so the
  // references of the two bins at the boundary are gathered in the middle of the range,
  // sorted by centroid, and the exact SAH split among them is taken (the binned split is one
  // of the candidates: never worse). Returns the split's cost.
  float refine_and_partition(int axis, int split, const BinMapping& map, float inv_area,
                             const RangeInfo& info, PrimRef* src, PrimRef* dst, RangeInfo& left,
                             RangeInfo& right) const {
    const float below = float(split - 1), above = float(split + 1);  // middle: bins split-1, split
    // One pass: lower bins to the front of dst, upper bins to its back, the middle packed at
    // the front of src's own range, which the pass has already read (every reference written
    // to one of three places, chosen by selects).
    thread_local std::vector<uint64_t> order, order_tmp;
    thread_local std::vector<float> suffix_area;
    const size_t b = info.begin, e = info.end;
    PrimRef* middle = src + b;
    SideBounds lower, upper;
    size_t f = b, k = e, t = 0;
    for (size_t i = b; i < e; ++i) {
      const Vec4f lo = ref_lo(src, i), hi = ref_hi(src, i);
      const float x = position(src[i], axis, map);
      const bool is_lower = x < below, is_upper = !(x < above), is_middle = !is_lower && !is_upper;
      PrimRef* to = is_middle ? &middle[t] : dst + (is_lower ? f : k - 1);
      lo.store(&to->lo);
      hi.store(&to->hi);
      f += is_lower;
      k -= is_upper;
      t += is_middle;
      const Vec4f c = centroid2(lo, hi);
      lower.add_unless(lane_mask(!is_lower), lo, hi, c);
      upper.add_unless(lane_mask(!is_upper), lo, hi, c);
    }
    const size_t m = t, n_lower = f - b, n_upper = e - k;
    PrimRef* mid = dst + f;
    // Sorted as packed (order-preserving key bits, position) words into the gap. Ties keep
    // the pass's order, which is deterministic.
    order.resize(m);
    for (size_t q = 0; q < m; ++q) {
      const float key = (&middle[q].lo.x)[axis] + (&middle[q].hi.x)[axis];
      uint32_t bits;
      std::memcpy(&bits, &key, 4);
      bits = (bits & 0x80000000u) ? ~bits : bits | 0x80000000u;  // float order as unsigned order
      order[q] = uint64_t(bits) << 32 | uint32_t(q);
    }
    const uint64_t* sorted = order.data();
    if (m < radix_min) {
      std::sort(order.begin(), order.end());
    } else {  // stable on the key alone: ties keep q's order, as the sort on (key, q)
      order_tmp.resize(m);
      sorted = radix_sort_packed(order.data(), order_tmp.data(), m, 32, 32);
    }
    for (size_t q = 0; q < m; ++q) mid[q] = middle[uint32_t(sorted[q])];
    // Exact sweep over the m + 1 split positions in the middle.
    suffix_area.resize(m + 1);
    Vec4f lo = upper.geom_lo, hi = upper.geom_hi;
    suffix_area[m] = n_upper ? simd::half_area(lo, hi) : 0.0f;
    for (size_t q = m; q-- > 0;) {
      lo = min(lo, Vec4f::load(&mid[q].lo));
      hi = max(hi, Vec4f::load(&mid[q].hi));
      suffix_area[q] = simd::half_area(lo, hi);
    }
    lo = lower.geom_lo;
    hi = lower.geom_hi;
    float best_cost = std::numeric_limits<float>::infinity();
    size_t best_k = 0;
    for (size_t q = 0; q <= m; ++q) {
      if (q > 0) {
        lo = min(lo, Vec4f::load(&mid[q - 1].lo));
        hi = max(hi, Vec4f::load(&mid[q - 1].hi));
      }
      const size_t nl = n_lower + q, nr = n_upper + (m - q);
      if (nl == 0 || nr == 0) continue;
      const float c = split_cost(config, inv_area, simd::half_area(lo, hi), nl, suffix_area[q], nr);
      if (c < best_cost) {
        best_cost = c;
        best_k = q;
      }
    }
    left = lower.range(b, f + best_k);
    right = upper.range(f + best_k, e);
    for (size_t q = 0; q < m; ++q)
      (q < best_k ? left : right).add(Vec4f::load(&mid[q].lo), Vec4f::load(&mid[q].hi));
    return best_cost;
  }
};

}  // namespace

Bvh2 build_binned_sah(std::span<const PrimRef> input, const BuildConfig& config,
                      bool block_leaves) {
  const size_t n = input.size();
  Buffer<PrimRef> refs(n), spare(n);  // refs: copied from the input with the root's bounds
  NodeSlots slots(n);
  RawArray<uint32_t> ids(n);
  BinnedBuilder builder{config,
                        slots,
                        ids.data(),
                        int(config.bin_count),
                        n <= small_input ? exact_sweep_cap : exact_sweep_max,
                        block_leaves ? size_t(4) : size_t(0)};
  RangeInfo root = RangeInfo::empty_at(0);
  {
    const size_t chunks = chunk_count(n, binning_chunk);
    std::vector<RangeInfo> partial(chunks, RangeInfo::empty_at(0));
    parallel_for(0, chunks, 1, [&](size_t cb, size_t ce) {
      for (size_t c = cb; c < ce; ++c)
        for (size_t i = c * binning_chunk; i < std::min(n, (c + 1) * binning_chunk); ++i) {
          refs[i] = input[i];
          partial[c].add(BinnedBuilder::ref_lo(input.data(), i),
                         BinnedBuilder::ref_hi(input.data(), i));
        }
    });
    for (const RangeInfo& p : partial) {
      root.geom_lo = min(root.geom_lo, p.geom_lo);
      root.geom_hi = max(root.geom_hi, p.geom_hi);
      root.cent_lo = min(root.cent_lo, p.cent_lo);
      root.cent_hi = max(root.cent_hi, p.cent_hi);
    }
    root.end = n;
  }
  builder.build(0, 1, root, refs.data(), spare.data());
  return compact_slots(slots, {ids.data(), n});
}

}  // namespace kestrel
