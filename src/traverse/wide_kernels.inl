// Wide-BVH traversal kernels, written once with GCC vector extensions and compiled once per
// instruction set (kernels_sse2.cpp, kernels_avx2.cpp, kernels_avx512.cpp), each with its
// own -m flags and its own namespace (KESTREL_ISA_NS). Everything here has internal linkage
// and no std template is instantiated, so no ISA-specific code can leak into another file.
//
// Results are bit-identical to the scalar reference (traverse_bvh2.h + watertight_hit):
//  - the triangle test performs the same float operations in the same order (the files are
//    compiled with -ffp-contract=off, so no FMA contraction), including the double-precision
//    retry when an edge function is exactly zero;
//  - box tests compute the entry and exit distances with the same operations as SlabRay, so
//    a node is visited whenever the scalar traversal would reach its leaves;
//  - closest-hit ties resolve to the smallest prim id (closer_hit), so the visiting order
//    does not matter.
#ifndef KESTREL_ISA_NS
#error "define KESTREL_ISA_NS before including wide_kernels.inl"
#endif

#include <immintrin.h>

#include <cstdint>

#include "traverse/kernels.h"

// Traversal statistics for experiments: a program that defines KESTREL_TRAVERSAL_STATS, the
// counters below, and includes this file with its own KESTREL_ISA_NS gets per-thread counts
// of rays, nodes visited, blocks tested and hit children per node (stat_hist[k] = nodes
// with k children hit). Off in the library.
#ifdef KESTREL_TRAVERSAL_STATS
namespace kestrel::kernels { extern thread_local uint64_t stat_nodes, stat_blocks, stat_rays, stat_hist[9]; }
#define KSTAT(x) (x)
#else
#define KSTAT(x) ((void)0)
#endif
namespace kestrel::kernels::KESTREL_ISA_NS {
namespace {

typedef float vf4 __attribute__((vector_size(16)));
typedef int32_t vi4 __attribute__((vector_size(16)));
typedef float vf8 __attribute__((vector_size(32)));
typedef int32_t vi8 __attribute__((vector_size(32)));
// Unaligned views for loads (nodes and blocks are aligned, but a plain load costs nothing).
typedef float vf4u __attribute__((vector_size(16), aligned(4)));
typedef float vf8u __attribute__((vector_size(32), aligned(4)));

template <int W> struct Simd;
template <> struct Simd<4> {
  using F = vf4;
  using I = vi4;
  static F load(const float* p) { return *reinterpret_cast<const vf4u*>(p); }
  static F splat(float x) { return F{x, x, x, x}; }
  static unsigned mask(I m) { return unsigned(_mm_movemask_ps(reinterpret_cast<__m128>(m))); }
};
template <> struct Simd<8> {
  using F = vf8;
  using I = vi8;
  static F load(const float* p) { return *reinterpret_cast<const vf8u*>(p); }
  static F splat(float x) { return F{x, x, x, x, x, x, x, x}; }
  static unsigned mask(I m) {
#ifdef __AVX__
    return unsigned(_mm256_movemask_ps(reinterpret_cast<__m256>(m)));
#else
    const vi4 lo = {m[0], m[1], m[2], m[3]}, hi = {m[4], m[5], m[6], m[7]};
    return Simd<4>::mask(lo) | Simd<4>::mask(hi) << 4;
#endif
  }
};

typedef float vf16 __attribute__((vector_size(64)));
typedef int32_t vi16 __attribute__((vector_size(64)));
typedef float vf16u __attribute__((vector_size(64), aligned(4)));
template <> struct Simd<16> {
  using F = vf16;
  using I = vi16;
  static F load(const float* p) { return *reinterpret_cast<const vf16u*>(p); }
  static F splat(float x) { return F{} + x; }
  static unsigned mask(I m) {
#ifdef __AVX512F__
    return unsigned(_mm512_cmplt_epi32_mask(reinterpret_cast<__m512i>(m), _mm512_setzero_si512()));
#else
    const vi8 lo = __builtin_shufflevector(m, m, 0, 1, 2, 3, 4, 5, 6, 7), hi = __builtin_shufflevector(m, m, 8, 9, 10, 11, 12, 13, 14, 15);
    return Simd<8>::mask(lo) | Simd<8>::mask(hi) << 8;
#endif
  }
};

// Same semantics as SlabRay::max_keep / min_keep: a NaN candidate keeps the accumulator.
template <class F> inline F vmax(F candidate, F acc) { return candidate > acc ? candidate : acc; }
template <class F> inline F vmin(F candidate, F acc) { return candidate < acc ? candidate : acc; }

inline unsigned ctz(unsigned m) { return unsigned(__builtin_ctz(m)); }

// As cull_distance in traverse_bvh2.h.
inline float cull_distance(float t) { return t + __builtin_fabsf(t) * 0x1p-12f; }

inline bool closer(float t, uint32_t id, float best_t, uint32_t best_id) {
  return t < best_t || (t == best_t && best_id != invalid_id && id < best_id);
}

// Per-ray constants of the watertight test (WatertightRay).
struct TriRay {
  float org[3], dir[3];
  int kx, ky, kz;
  float sx, sy, tmin;
  TriRay() = default;
  explicit TriRay(const Ray& r) { init(r); }
  void init(const Ray& r) {
    org[0] = r.org.x, org[1] = r.org.y, org[2] = r.org.z;
    dir[0] = r.dir.x, dir[1] = r.dir.y, dir[2] = r.dir.z;
    const float ax = __builtin_fabsf(dir[0]), ay = __builtin_fabsf(dir[1]), az = __builtin_fabsf(dir[2]);
    kz = ax >= ay ? (ax >= az ? 0 : 2) : (ay >= az ? 1 : 2);
    kx = kz == 2 ? 0 : kz + 1;
    ky = kx == 2 ? 0 : kx + 1;
    if (dir[kz] < 0.0f) {
      const int k = kx;
      kx = ky;
      ky = k;
    }
    sx = dir[kx] / dir[kz];
    sy = dir[ky] / dir[kz];
    tmin = r.tmin;
  }
};

// Candidate hits of one block: lanes with a hit at t > tmin, and the values the hit needs.
struct BlockHits {
  unsigned mask;
  vf4 t, v, w, det;
};

// The watertight test (watertight_hit) on four triangles at once.
inline BlockHits intersect_block(const TriRay& r, const TriangleBlock& blk) {
  using S = Simd<4>;
  BlockHits out;
  const float* V0 = &blk.v[0][0][0];
  const float* V1 = &blk.v[1][0][0];
  const float* V2 = &blk.v[2][0][0];
  const int kx = r.kx * 4, ky = r.ky * 4, kz = r.kz * 4;
  const vf4 okx = S::splat(r.org[r.kx]), oky = S::splat(r.org[r.ky]), okz = S::splat(r.org[r.kz]);
  const vf4 sx = S::splat(r.sx), sy = S::splat(r.sy);
  // Vertices relative to the origin, in the permuted axes, then sheared.
  const vf4 akx = S::load(V0 + kx) - okx, aky = S::load(V0 + ky) - oky, akz = S::load(V0 + kz) - okz;
  const vf4 bkx = S::load(V1 + kx) - okx, bky = S::load(V1 + ky) - oky, bkz = S::load(V1 + kz) - okz;
  const vf4 ckx = S::load(V2 + kx) - okx, cky = S::load(V2 + ky) - oky, ckz = S::load(V2 + kz) - okz;
  const vf4 ax = akx - sx * akz, ay = aky - sy * akz;
  const vf4 bx = bkx - sx * bkz, by = bky - sy * bkz;
  const vf4 cx = ckx - sx * ckz, cy = cky - sy * ckz;
  vf4 u = cx * by - cy * bx;
  vf4 v = ax * cy - ay * cx;
  vf4 w = bx * ay - by * ax;
  const vf4 zero = {};
  vf4 det = u + v + w;
  // Exact zeros (the double retry) and NaN (from overflowing products) take the slow path.
  const unsigned slow = S::mask((u == zero) | (v == zero) | (w == zero) | (det != det));
  vi4 ok;
  if (__builtin_expect(slow == 0, 1)) {
    // No edge function is zero: the ray is inside when all three signs agree.
    const vi4 ui = reinterpret_cast<vi4>(u), vi = reinterpret_cast<vi4>(v), wi = reinterpret_cast<vi4>(w);
    ok = ((ui ^ vi) | (ui ^ wi)) >= vi4{};
  } else {
    unsigned retry = S::mask((u == zero) | (v == zero) | (w == zero));
    while (retry) {  // rare: an edge function is exactly 0; redo this lane in double
      const unsigned i = ctz(retry);
      retry &= retry - 1;
      u[i] = float(double(cx[i]) * by[i] - double(cy[i]) * bx[i]);
      v[i] = float(double(ax[i]) * cy[i] - double(ay[i]) * cx[i]);
      w[i] = float(double(bx[i]) * ay[i] - double(by[i]) * ax[i]);
    }
    const vi4 neg = (u < zero) | (v < zero) | (w < zero);
    const vi4 pos = (u > zero) | (v > zero) | (w > zero);
    ok = ~(neg & pos);
    det = u + v + w;
  }
  ok &= det != zero;
  out.mask = S::mask(ok);
  if (!out.mask) return out;
  // Distance from the plane equation in the permuted axes (as watertight_hit).
  const vf4 e10 = bkx - akx, e11 = bky - aky, e12 = bkz - akz;
  const vf4 e20 = ckx - akx, e21 = cky - aky, e22 = ckz - akz;
  const vf4 n0 = e11 * e22 - e12 * e21;
  const vf4 n1 = e12 * e20 - e10 * e22;
  const vf4 n2 = e10 * e21 - e11 * e20;
  const vf4 ndd = n0 * S::splat(r.dir[r.kx]) + n1 * S::splat(r.dir[r.ky]) + n2 * S::splat(r.dir[r.kz]);
  const vf4 t = (n0 * akx + n1 * aky + n2 * akz) / ndd;
  ok &= (ndd != zero) & (t > S::splat(r.tmin));
  out.mask = S::mask(ok);
  out.t = t;
  out.v = v;
  out.w = w;
  out.det = det;
  return out;
}

// Per-ray constants of the box test (SlabRay), splatted to W lanes.
inline float far_scale(float inv) { return inv * 1.00000072f; }
template <int W> struct BoxRay {
  using F = typename Simd<W>::F;
  F org[3], inv[3], inv_far[3];
  mutable typename Simd<W>::I test_mask;  // lanes hit by the last test (all ones / zeros)
  int near_row[3], far_row[3];  // rows of Bvh*Node::bounds holding the near / far planes
  BoxRay() = default;
  explicit BoxRay(const Ray& r) { init(r); }
  void init(const Ray& r) {
    const float d[3] = {r.dir.x, r.dir.y, r.dir.z}, o[3] = {r.org.x, r.org.y, r.org.z};
    for (int a = 0; a < 3; ++a) {
      org[a] = Simd<W>::splat(o[a]);
      inv[a] = Simd<W>::splat(1.0f / d[a]);
      inv_far[a] = Simd<W>::splat(far_scale(1.0f / d[a]));
      const int hi_first = __builtin_signbit(d[a]) ? 1 : 0;
      near_row[a] = 2 * a + hi_first;
      far_row[a] = 2 * a + 1 - hi_first;
    }
  }
  // Lanes whose box overlaps (tmin, tmax); entry distances in tnear.
  unsigned test(const float (*bounds)[W], F tmin, F tmax, F& tnear) const {
    using S = Simd<W>;
    const F nx = (S::load(bounds[near_row[0]]) - org[0]) * inv[0];
    const F ny = (S::load(bounds[near_row[1]]) - org[1]) * inv[1];
    const F nz = (S::load(bounds[near_row[2]]) - org[2]) * inv[2];
    const F fx = (S::load(bounds[far_row[0]]) - org[0]) * inv_far[0];
    const F fy = (S::load(bounds[far_row[1]]) - org[1]) * inv_far[1];
    const F fz = (S::load(bounds[far_row[2]]) - org[2]) * inv_far[2];
    tnear = vmax(nz, vmax(ny, vmax(nx, tmin)));
    const F tfar = vmin(fz, vmin(fy, vmin(fx, tmax)));
    test_mask = tnear <= tfar;
    return S::mask(test_mask);
  }
};

struct StackEntry {
  uint32_t ref;
  float dist;
};

#ifdef __AVX2__
// Sorts the hit children of an 8-wide node by entry distance without branches: keys are
// the distance's bits made monotonic as signed integers, low 3 bits replaced by the lane,
// misses set to INT_MAX; a bitonic network of six compare-exchange stages sorts them in
// one register. The nearest child is returned; the others go on the stack, farthest
// first, in one 64-byte store (the stack has room for a full node beyond its top).
inline __m256i cmpx(__m256i v, __m256i partner_idx, int take_max) {
  const __m256i p = _mm256_permutevar8x32_epi32(v, partner_idx);
  const __m256i lo = _mm256_min_epi32(v, p), hi = _mm256_max_epi32(v, p);
  switch (take_max) {  // blend needs an immediate
    case 0xAA: return _mm256_blend_epi32(lo, hi, 0xAA);
    case 0xCC: return _mm256_blend_epi32(lo, hi, 0xCC);
    case 0xF0: return _mm256_blend_epi32(lo, hi, 0xF0);
    case 0x66: return _mm256_blend_epi32(lo, hi, 0x66);
    case 0x3C: return _mm256_blend_epi32(lo, hi, 0x3C);
    default: return _mm256_blend_epi32(lo, hi, 0x5A);
  }
}

inline uint32_t push_sorted8(const uint32_t* child, vf8 tnear, vi8 hit, StackEntry*& sp) {
  const __m256i iota = _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7);
  __m256i bits = _mm256_castps_si256(reinterpret_cast<__m256>(tnear));
  // Negative floats: flip the magnitude bits so integer order is float order.
  bits = _mm256_xor_si256(bits, _mm256_srli_epi32(_mm256_srai_epi32(bits, 31), 1));
  __m256i key = _mm256_or_si256(_mm256_andnot_si256(_mm256_set1_epi32(7), bits), iota);
  key = _mm256_blendv_epi8(_mm256_set1_epi32(0x7FFFFFFF), key, reinterpret_cast<__m256i>(hit));
  // Bitonic sort, ascending: stages (k, j) = (2,1) (4,2) (4,1) (8,4) (8,2) (8,1); lane i
  // pairs with i ^ j and keeps the max when ((i & j) != 0) == ((i & k) == 0).
  key = cmpx(key, _mm256_setr_epi32(1, 0, 3, 2, 5, 4, 7, 6), 0x66);
  key = cmpx(key, _mm256_setr_epi32(2, 3, 0, 1, 6, 7, 4, 5), 0x3C);
  key = cmpx(key, _mm256_setr_epi32(1, 0, 3, 2, 5, 4, 7, 6), 0x5A);
  key = cmpx(key, _mm256_setr_epi32(4, 5, 6, 7, 0, 1, 2, 3), 0xF0);
  key = cmpx(key, _mm256_setr_epi32(2, 3, 0, 1, 6, 7, 4, 5), 0xCC);
  key = cmpx(key, _mm256_setr_epi32(1, 0, 3, 2, 5, 4, 7, 6), 0xAA);
  const __m256i lane = _mm256_and_si256(key, _mm256_set1_epi32(7));
  const int n = __builtin_popcount(unsigned(_mm256_movemask_ps(reinterpret_cast<__m256>(hit))));
  // Reverse the first n sorted entries: slot i gets sorted entry n-1-i (slot n-1 = nearest).
  const __m256i rev = _mm256_and_si256(_mm256_sub_epi32(_mm256_set1_epi32(n - 1), iota), _mm256_set1_epi32(7));
  const __m256i order = _mm256_permutevar8x32_epi32(lane, rev);
  const __m256i refs = _mm256_permutevar8x32_epi32(_mm256_loadu_si256(reinterpret_cast<const __m256i*>(child)), order);
  const __m256i dists = _mm256_permutevar8x32_epi32(_mm256_castps_si256(reinterpret_cast<__m256>(tnear)), order);
  const __m256i lo = _mm256_unpacklo_epi32(refs, dists), hi = _mm256_unpackhi_epi32(refs, dists);
  _mm256_storeu_si256(reinterpret_cast<__m256i*>(sp), _mm256_permute2x128_si256(lo, hi, 0x20));
  _mm256_storeu_si256(reinterpret_cast<__m256i*>(sp) + 1, _mm256_permute2x128_si256(lo, hi, 0x31));
  sp += n - 1;
  return sp->ref;  // slot n-1: the nearest, not part of the stack
}
#endif

// Deepest wide tree: the Bvh2 depth bound (255) with at most W-1 entries pushed per level.
template <int W> inline constexpr int stack_size = 256 * (W - 1) + 1 + 8;

// Walks a wide BVH nearest child first. leaf(ref) handles a leaf reference: it may lower
// best_t (closest hit) and returns true to stop (any hit). Node is Bvh4Node or Bvh8Node.
template <int W, bool AnyHit, class Node, class LeafFn>
inline void traverse(const Node* nodes, const BoxRay<W>& box, float tmin_s, float& best_t, LeafFn&& leaf) {
  using S = Simd<W>;
  using F = typename S::F;
  const F tmin = S::splat(tmin_s);
  float cull_t = AnyHit ? best_t : cull_distance(best_t);
  F tmax = S::splat(cull_t);
  StackEntry stack[stack_size<W>];
  StackEntry* sp = stack;
  uint32_t cur = 0;  // the root is an inner node
  while (true) {
    // Descend through inner nodes, nearest child first.
    while (!(cur & wide_leaf_bit)) {
      const Node& node = nodes[cur];
      KSTAT(++stat_nodes);
      F tnear;
      unsigned m = box.test(node.bounds, tmin, tmax, tnear);
      KSTAT(++stat_hist[__builtin_popcount(m)]);
      if (!m) goto pop;
      unsigned r = ctz(m);
      m &= m - 1;
      if constexpr (AnyHit) {  // order does not matter for occlusion: no sorting
        cur = node.child[r];
        while (m) {
          r = ctz(m);
          m &= m - 1;
          *sp++ = {node.child[r], 0.0f};
        }
        continue;
      }
      const uint32_t c0 = node.child[r];
      const float d0 = tnear[r];
      if (!m) {
        cur = c0;
        continue;
      }
      r = ctz(m);
      m &= m - 1;
      const uint32_t c1 = node.child[r];
      const float d1 = tnear[r];
      if (!m) {
        if (d0 <= d1) {
          *sp++ = {c1, d1};
          cur = c0;
        } else {
          *sp++ = {c0, d0};
          cur = c1;
        }
        continue;
      }
      // Three or more: push all, nearest on top, and continue with the nearest.
#ifdef __AVX2__
      if constexpr (W == 8) {
        cur = push_sorted8(node.child, tnear, box.test_mask, sp);
        continue;
      }
#endif
      {
        StackEntry* base = sp;
        *sp++ = {c0, d0};
        *sp++ = {c1, d1};
        do {
          r = ctz(m);
          m &= m - 1;
          *sp++ = {node.child[r], tnear[r]};
        } while (m);
        for (StackEntry* i = base + 1; i < sp; ++i) {
          const StackEntry e = *i;
          StackEntry* j = i;
          for (; j > base && j[-1].dist < e.dist; --j) *j = j[-1];
          *j = e;
        }
        cur = (--sp)->ref;
      }
    }
    if (cur != wide_empty) {
      if (leaf(cur) && AnyHit) return;
      if (!AnyHit) {
        cull_t = cull_distance(best_t);
        tmax = S::splat(cull_t);
      }
    }
  pop:
    while (true) {
      if (sp == stack) return;
      --sp;
      if (AnyHit || sp->dist <= cull_t) break;
    }
    cur = sp->ref;
  }
}

// The closest (or any) triangle hit of one ray in one wide BVH.
template <int W, bool AnyHit, class Node>
inline void trace_ray(const Node* nodes, const TriangleBlock* blocks, const Ray& ray, Hit& hit) {
  const BoxRay<W> box(ray);
  const TriRay tri(ray);
  KSTAT(++stat_rays);
  float best_t = ray.tmax;
  uint32_t best_id = invalid_id;
  float best_v = 0, best_w = 0, best_det = 1;
  traverse<W, AnyHit>(nodes, box, ray.tmin, best_t, [&](uint32_t ref) {
    // A leaf: its blocks until the one flagged last.
    for (const TriangleBlock* blk = blocks + (ref & ~wide_leaf_bit);; ++blk) {
      const BlockHits h = intersect_block(tri, *blk);
      KSTAT(++stat_blocks);
      unsigned m = h.mask;
      while (m) {
        const unsigned i = ctz(m);
        m &= m - 1;
        const float t = h.t[i];
        const uint32_t id = blk->prim_id[i] & ~block_last_bit;
        if constexpr (AnyHit) {
          if (t < best_t) {
            best_t = t;
            best_id = id;
            return true;
          }
        } else if (closer(t, id, best_t, best_id)) {
          best_t = t;
          best_id = id;
          best_v = h.v[i];
          best_w = h.w[i];
          best_det = h.det[i];
        }
      }
      if (blk->prim_id[0] & block_last_bit) return false;
    }
  });
  if (best_id != invalid_id) {
    hit.t = best_t;
    hit.prim_id = best_id;
    if (AnyHit) {
      hit.u = hit.v = 0;
    } else {
      const float inv_det = 1.0f / best_det;
      hit.u = best_v * inv_det;
      hit.v = best_w * inv_det;
    }
  } else {
    hit.t = __builtin_inff();
    hit.prim_id = invalid_id;
    hit.u = hit.v = 0;
  }
}

// Storage for a Hit without running Hit's (shared, inline) constructor: this union's
// constructor has internal linkage. trace_ray writes every field.
union HitStorage {
  Hit hit;
  HitStorage() {}
};

// Two levels: the TLAS's leaves are instances; the ray enters each instance's BLAS in object
// space (t is unchanged by an affine map of origin and direction together).
inline void to_object(const float* m, const Ray& r, Ray& out) {
  const Vec3 o = r.org, d = r.dir;
  out.org = {m[0] * o.x + m[1] * o.y + m[2] * o.z + m[3], m[4] * o.x + m[5] * o.y + m[6] * o.z + m[7],
             m[8] * o.x + m[9] * o.y + m[10] * o.z + m[11]};
  out.dir = {m[0] * d.x + m[1] * d.y + m[2] * d.z, m[4] * d.x + m[5] * d.y + m[6] * d.z, m[8] * d.x + m[9] * d.y + m[10] * d.z};
  out.tmin = r.tmin;
}

template <int W, bool AnyHit, class Node>
void trace_tlas(const void* tlas_nodes, const InstanceData* instances, const Ray* rays, InstanceHit* hits, size_t n,
                uint32_t ray_mask) {
  const Node* tlas = static_cast<const Node*>(tlas_nodes);
  for (size_t k = 0; k < n; ++k) {
    const Ray& ray = rays[k];
    const BoxRay<W> box(ray);
    // Public types are copied, never default-constructed here: their implicit constructors
    // are inline functions the linker could share with code for other ISAs.
    InstanceHit best = hits[k];
    best.t = ray.tmax;
    best.prim_id = best.instance_id = invalid_id;
    best.u = best.v = 0;
    traverse<W, AnyHit>(tlas, box, ray.tmin, best.t, [&](uint32_t ref) {
      const InstanceData& inst = instances[ref & ~wide_leaf_bit];
      if (!(inst.mask & ray_mask)) return false;
      Ray local = ray;
      to_object(inst.world_to_object, ray, local);
      if (local.dir.x == 0.0f && local.dir.y == 0.0f && local.dir.z == 0.0f) return false;
      // Closest hit: a hit at exactly best.t in another instance is a tie, resolved to the
      // smaller (instance, prim) like the flattened scene's smallest id, whatever the order.
      local.tmax = AnyHit ? best.t : __builtin_nextafterf(best.t, __builtin_inff());
      HitStorage storage;
      Hit& h = storage.hit;
      trace_ray<W, AnyHit>(static_cast<const Node*>(inst.nodes), inst.blocks, local, h);
      if (h.prim_id == invalid_id) return false;
      if (!AnyHit && !(h.t < best.t || (h.t == best.t && best.instance_id != invalid_id && inst.id < best.instance_id)))
        return false;
      best.t = h.t;
      best.prim_id = h.prim_id;
      best.instance_id = inst.id;
      best.u = h.u;
      best.v = h.v;
      return true;
    });
    if (best.instance_id == invalid_id) best.t = __builtin_inff();
    hits[k] = best;
  }
}

template <int W, bool AnyHit, class Node>
void trace_batch(const Node* nodes, const TriangleBlock* blocks, const Ray* rays, Hit* hits, size_t n) {
  for (size_t i = 0; i < n; ++i) trace_ray<W, AnyHit>(nodes, blocks, rays[i], hits[i]);
}

// Packets of up to 8 rays (closest hit). The packet walks one traversal order and fetches
// each node once; every stack entry carries the rays whose own box test reached it, and a
// ray is tested only against boxes and leaves its single-ray traversal could visit, with
// the same operations, so the hits are identical to single rays. What a packet saves is
// per-ray control flow (one ordering decision per node for all its rays) and repeated node
// fetches; the box and triangle arithmetic stays per ray.
inline uint64_t transpose8x8(uint64_t x) {
  // Bit (r, j) = bit 8r + j moves to 8j + r (Hacker's Delight 7-3).
  uint64_t t = (x ^ (x >> 7)) & 0x00AA00AA00AA00AAull;
  x ^= t ^ (t << 7);
  t = (x ^ (x >> 14)) & 0x0000CCCC0000CCCCull;
  x ^= t ^ (t << 14);
  t = (x ^ (x >> 28)) & 0x00000000F0F0F0F0ull;
  x ^= t ^ (t << 28);
  return x;
}

template <int W, class Node>
void trace_packet(const Node* nodes, const TriangleBlock* blocks, const Ray* rays, Hit* hits, unsigned n) {
  using S = Simd<W>;
  using F = typename S::F;
  struct Lane {
    BoxRay<W> box;
    TriRay tri;
    F tmin;
    float best_t, cull_t, best_v, best_w, best_det;
    uint32_t best_id;
  } lane[8];
  for (unsigned r = 0; r < n; ++r) {
    Lane& L = lane[r];
    L.box.init(rays[r]);
    L.tri.init(rays[r]);
    L.tmin = S::splat(rays[r].tmin);
    L.best_t = rays[r].tmax;
    L.cull_t = cull_distance(L.best_t);
    L.best_id = invalid_id;
    L.best_v = L.best_w = 0;
    L.best_det = 1;
  }
  struct Entry {
    uint32_t ref;
    uint32_t rays;
    float dist;
  };
  Entry stack[stack_size<W>];
  Entry* sp = stack;
  uint32_t cur = 0;
  unsigned cur_rays = (1u << n) - 1;
  const F inf = S::splat(__builtin_inff());
  while (true) {
    if (!(cur & wide_leaf_bit)) {
      const Node& node = nodes[cur];
      uint64_t masks = 0;
      F dmin = inf;
      for (unsigned rs = cur_rays; rs; rs &= rs - 1) {
        const unsigned r = ctz(rs);
        F tn;
        const uint64_t m = lane[r].box.test(node.bounds, lane[r].tmin, S::splat(lane[r].cull_t), tn);
        masks |= m << (8 * r);
        dmin = vmin(lane[r].box.test_mask != 0 ? tn : inf, dmin);
      }
      const uint64_t by_child = transpose8x8(masks);  // byte j: rays that hit child j
      unsigned hit_children = 0;
      for (int j = 0; j < W; ++j) hit_children |= unsigned((by_child >> (8 * j)) & 0xFF) != 0 ? 1u << j : 0u;
      if (!hit_children) goto pop;
      // Push farthest first (by the nearest entry over the packet's rays).
      Entry* base = sp;
      for (unsigned m = hit_children; m; m &= m - 1) {
        const unsigned j = ctz(m);
        Entry e{node.child[j], unsigned((by_child >> (8 * j)) & 0xFF), dmin[j]};
        Entry* k = sp++;
        for (; k > base && k[-1].dist < e.dist; --k) *k = k[-1];
        *k = e;
      }
      --sp;
      cur = sp->ref;
      cur_rays = sp->rays;
      continue;
    }
    for (unsigned rs = cur_rays; rs; rs &= rs - 1) {
      Lane& L = lane[ctz(rs)];
      for (const TriangleBlock* blk = blocks + (cur & ~wide_leaf_bit);; ++blk) {
        const BlockHits h = intersect_block(L.tri, *blk);
        for (unsigned m = h.mask; m; m &= m - 1) {
          const unsigned i = ctz(m);
          const uint32_t id = blk->prim_id[i] & ~block_last_bit;
          if (closer(h.t[i], id, L.best_t, L.best_id)) {
            L.best_t = h.t[i];
            L.best_id = id;
            L.best_v = h.v[i];
            L.best_w = h.w[i];
            L.best_det = h.det[i];
          }
        }
        if (blk->prim_id[0] & block_last_bit) break;
      }
      L.cull_t = cull_distance(L.best_t);
    }
  pop:
    while (true) {
      if (sp == stack) goto done;
      --sp;
      // Keep the rays whose best hit may still lie beyond the entry's nearest point.
      unsigned keep = 0;
      for (unsigned rs = sp->rays; rs; rs &= rs - 1) {
        const unsigned r = ctz(rs);
        if (sp->dist <= lane[r].cull_t) keep |= 1u << r;
      }
      if (keep) {
        cur = sp->ref;
        cur_rays = keep;
        break;
      }
    }
  }
done:
  for (unsigned r = 0; r < n; ++r) {
    const Lane& L = lane[r];
    Hit& hit = hits[r];
    if (L.best_id != invalid_id) {
      const float inv_det = 1.0f / L.best_det;
      hit.t = L.best_t;
      hit.prim_id = L.best_id;
      hit.u = L.best_v * inv_det;
      hit.v = L.best_w * inv_det;
    } else {
      hit.t = __builtin_inff();
      hit.prim_id = invalid_id;
      hit.u = hit.v = 0;
    }
  }
}

#ifdef __AVX2__
// Coherent packets, L rays (8, or 16 with AVX-512) in the lanes of every vector: each child box of a node is tested
// against all rays at once and each triangle of a leaf against all rays at once, so the
// control flow (which children, in which order, which leaves) is decided once per packet.
// Needs rays that agree on their direction signs (near planes) and on the watertight test's
// axis permutation (kx, ky, kz); the caller falls back otherwise. Every per-ray operation is
// the single-ray kernel's, lane by lane, so the hits are identical.
template <class V, class M> inline V select_lanes(M m, V a, V b) { return m != M{} ? a : b; }

// Horizontal minimum, broadcast to every lane.
inline vf8 hmin_lanes(vf8 d) {
  d = vmin(d, __builtin_shufflevector(d, d, 4, 5, 6, 7, 0, 1, 2, 3));
  d = vmin(d, __builtin_shufflevector(d, d, 2, 3, 0, 1, 6, 7, 4, 5));
  return vmin(d, __builtin_shufflevector(d, d, 1, 0, 3, 2, 5, 4, 7, 6));
}
inline vf16 hmin_lanes(vf16 d) {
  d = vmin(d, __builtin_shufflevector(d, d, 8, 9, 10, 11, 12, 13, 14, 15, 0, 1, 2, 3, 4, 5, 6, 7));
  d = vmin(d, __builtin_shufflevector(d, d, 4, 5, 6, 7, 0, 1, 2, 3, 12, 13, 14, 15, 8, 9, 10, 11));
  d = vmin(d, __builtin_shufflevector(d, d, 2, 3, 0, 1, 6, 7, 4, 5, 10, 11, 8, 9, 14, 15, 12, 13));
  return vmin(d, __builtin_shufflevector(d, d, 1, 0, 3, 2, 5, 4, 7, 6, 9, 8, 11, 10, 13, 12, 15, 14));
}

// AnyHit: occlusion; a lane leaves the packet at its first hit (t < tmax), children are not
// sorted, and the packet ends when every lane is done.
template <int L, bool AnyHit>
bool trace_packet_lanes(const Bvh8Node* nodes, const TriangleBlock* blocks, const Ray* rays, Hit* hits, unsigned n) {
  using S = Simd<L>;
  using VF = typename S::F;
  using VI = typename S::I;
  const auto bcast = [](float x) { return S::splat(x); };
  TriRay tr[L];
  for (unsigned r = 0; r < n; ++r) {
    tr[r].init(rays[r]);
    if (tr[r].kx != tr[0].kx || tr[r].ky != tr[0].ky || tr[r].kz != tr[0].kz) return false;
    if (__builtin_signbit(rays[r].dir.x) != __builtin_signbit(rays[0].dir.x) ||
        __builtin_signbit(rays[r].dir.y) != __builtin_signbit(rays[0].dir.y) ||
        __builtin_signbit(rays[r].dir.z) != __builtin_signbit(rays[0].dir.z))
      return false;
  }
  alignas(64) float o[3][L], inv[3][L], inv_far[3][L], tmin_a[L], tmax_a[L], sx_a[L], sy_a[L], okx_a[L], oky_a[L], okz_a[L],
      dkx_a[L], dky_a[L], dkz_a[L];
  const int kx = tr[0].kx, ky = tr[0].ky, kz = tr[0].kz;
  for (unsigned l = 0; l < unsigned(L); ++l) {
    const unsigned r = l < n ? l : n - 1;  // idle lanes repeat the last ray, masked out
    const float d[3] = {rays[r].dir.x, rays[r].dir.y, rays[r].dir.z};
    const float org[3] = {rays[r].org.x, rays[r].org.y, rays[r].org.z};
    for (int a = 0; a < 3; ++a) {
      o[a][l] = org[a];
      inv[a][l] = 1.0f / d[a];
      inv_far[a][l] = far_scale(1.0f / d[a]);
    }
    tmin_a[l] = rays[r].tmin;
    tmax_a[l] = rays[r].tmax;
    sx_a[l] = tr[r].sx, sy_a[l] = tr[r].sy;
    okx_a[l] = org[kx], oky_a[l] = org[ky], okz_a[l] = org[kz];
    dkx_a[l] = d[kx], dky_a[l] = d[ky], dkz_a[l] = d[kz];
  }
  const VF ox = S::load(o[0]), oy = S::load(o[1]), oz = S::load(o[2]);
  const VF ix = S::load(inv[0]), iy = S::load(inv[1]), iz = S::load(inv[2]);
  const VF fx = S::load(inv_far[0]), fy = S::load(inv_far[1]), fz = S::load(inv_far[2]);
  const VF tmin = S::load(tmin_a), sx = S::load(sx_a), sy = S::load(sy_a);
  const VF okx = S::load(okx_a), oky = S::load(oky_a), okz = S::load(okz_a);
  const VF dkx = S::load(dkx_a), dky = S::load(dky_a), dkz = S::load(dkz_a);
  const VF inf = bcast(__builtin_inff()), zero = {};
  VI lane_index;
  for (int l = 0; l < L; ++l) lane_index[l] = l;
  VF best_t = S::load(tmax_a), best_v = zero, best_w = zero, best_det = bcast(1.0f);
  VI best_id = VI{} - 1;  // invalid_id in every lane
  const VF scale = bcast(0x1p-12f);
  auto cull_of = [&](VF t) { return t + (t < zero ? -t : t) * scale; };
  VF cull = AnyHit ? best_t : cull_of(best_t);  // any hit: the ray's own tmax, as the single-ray kernel
  unsigned done = 0;                             // any hit: lanes that found their hit
  const int nrx = __builtin_signbit(rays[0].dir.x) ? 1 : 0, nry = 2 + (__builtin_signbit(rays[0].dir.y) ? 1 : 0),
            nrz = 4 + (__builtin_signbit(rays[0].dir.z) ? 1 : 0);
  struct Entry {
    uint32_t ref, rays;
    float dist;
  };
  Entry stack[stack_size<8>];
  Entry* sp = stack;
  uint32_t cur = 0;
  unsigned cur_rays = (1u << n) - 1;
  while (true) {
    if (!(cur & wide_leaf_bit)) {
      const Bvh8Node& node = nodes[cur];
      cur_rays &= ~done;
      const VI active = ((VI{} + int(cur_rays)) >> lane_index & 1) != 0;
      Entry* base = sp;
      for (int j = 0; j < 8; ++j) {
        if (node.child[j] == wide_empty) continue;
        const VF nx = (bcast(node.bounds[nrx][j]) - ox) * ix, ny = (bcast(node.bounds[nry][j]) - oy) * iy,
                  nz = (bcast(node.bounds[nrz][j]) - oz) * iz;
        const VF gx = (bcast(node.bounds[nrx ^ 1][j]) - ox) * fx, gy = (bcast(node.bounds[nry ^ 1][j]) - oy) * fy,
                  gz = (bcast(node.bounds[nrz ^ 1][j]) - oz) * fz;
        const VF tn = vmax(nz, vmax(ny, vmax(nx, tmin)));
        const VF tf = vmin(gz, vmin(gy, vmin(gx, cull)));
        const VI hit = (tn <= tf) & active;
        const unsigned m = S::mask(hit);
        if (!m) continue;
        if constexpr (AnyHit) {
          *sp++ = {node.child[j], m, 0.0f};
          continue;
        }
        const VF d = hmin_lanes(select_lanes(hit, tn, inf));
        const Entry e{node.child[j], m, d[0]};
        Entry* k = sp++;  // farthest first: the nearest ends on top
        for (; k > base && k[-1].dist < e.dist; --k) *k = k[-1];
        *k = e;
      }
      if (sp == base) goto pop;
      --sp;
      cur = sp->ref;
      cur_rays = sp->rays;
      continue;
    }
    {
      cur_rays &= ~done;
      const VI active = ((VI{} + int(cur_rays)) >> lane_index & 1) != 0;
      for (const TriangleBlock* blk = blocks + (cur & ~wide_leaf_bit);; ++blk) {
        for (int i = 0; i < 4; ++i) {
          const VF akz = bcast(blk->v[0][kz][i]) - okz, bkz = bcast(blk->v[1][kz][i]) - okz, ckz = bcast(blk->v[2][kz][i]) - okz;
          const VF akx = bcast(blk->v[0][kx][i]) - okx, aky = bcast(blk->v[0][ky][i]) - oky;
          const VF bkx = bcast(blk->v[1][kx][i]) - okx, bky = bcast(blk->v[1][ky][i]) - oky;
          const VF ckx = bcast(blk->v[2][kx][i]) - okx, cky = bcast(blk->v[2][ky][i]) - oky;
          const VF ax = akx - sx * akz, ay = aky - sy * akz;
          const VF bx = bkx - sx * bkz, by = bky - sy * bkz;
          const VF cx = ckx - sx * ckz, cy = cky - sy * ckz;
          VF u = cx * by - cy * bx, v = ax * cy - ay * cx, w = bx * ay - by * ax;
          VF det = u + v + w;
          VI ok;
          const unsigned slow = S::mask((u == zero) | (v == zero) | (w == zero) | (det != det));
          if (__builtin_expect(slow == 0, 1)) {
            const VI ui = reinterpret_cast<VI>(u), vi = reinterpret_cast<VI>(v), wi = reinterpret_cast<VI>(w);
            ok = ((ui ^ vi) | (ui ^ wi)) >= VI{};
          } else {
            unsigned retry = S::mask((u == zero) | (v == zero) | (w == zero));
            while (retry) {
              const unsigned l = ctz(retry);
              retry &= retry - 1;
              u[l] = float(double(cx[l]) * by[l] - double(cy[l]) * bx[l]);
              v[l] = float(double(ax[l]) * cy[l] - double(ay[l]) * cx[l]);
              w[l] = float(double(bx[l]) * ay[l] - double(by[l]) * ax[l]);
            }
            const VI neg = (u < zero) | (v < zero) | (w < zero);
            const VI pos = (u > zero) | (v > zero) | (w > zero);
            ok = ~(neg & pos);
            det = u + v + w;
          }
          ok &= (det != zero) & active;
          if (!S::mask(ok)) continue;
          const VF e10 = bkx - akx, e11 = bky - aky, e12 = bkz - akz;
          const VF e20 = ckx - akx, e21 = cky - aky, e22 = ckz - akz;
          const VF n0 = e11 * e22 - e12 * e21, n1 = e12 * e20 - e10 * e22, n2 = e10 * e21 - e11 * e20;
          const VF ndd = n0 * dkx + n1 * dky + n2 * dkz;
          const VF t = (n0 * akx + n1 * aky + n2 * akz) / ndd;
          const VI id = VI{} + int(blk->prim_id[i] & ~block_last_bit);
          if constexpr (AnyHit) {
            const VI found = ok & (ndd != zero) & (t > tmin) & (t < best_t) & (best_id == VI{} - 1);
            const unsigned f = S::mask(found);
            if (!f) continue;
            best_t = select_lanes(found, t, best_t);
            best_id = select_lanes(found, id, best_id);
            done |= f;
            continue;
          }
          // closer(): nearer, or equally near with a smaller id once a hit exists.
          const VI better = ok & (ndd != zero) & (t > tmin) &
                             ((t < best_t) | ((t == best_t) & (best_id != VI{} - 1) & (id < best_id)));
          if (!S::mask(better)) continue;
          best_t = select_lanes(better, t, best_t);
          best_id = select_lanes(better, id, best_id);
          best_v = select_lanes(better, v, best_v);
          best_w = select_lanes(better, w, best_w);
          best_det = select_lanes(better, det, best_det);
        }
        if (blk->prim_id[0] & block_last_bit) break;
      }
      if (!AnyHit) cull = cull_of(best_t);
    }
  pop:
    while (true) {
      if (sp == stack || (AnyHit && done == (1u << n) - 1)) goto finish;
      --sp;
      // Rays whose best hit may lie beyond the entry's nearest point (any hit: not done).
      const unsigned keep = AnyHit ? sp->rays & ~done : sp->rays & S::mask(bcast(sp->dist) <= cull);
      if (keep) {
        cur = sp->ref;
        cur_rays = keep;
        break;
      }
    }
  }
finish:
  for (unsigned r = 0; r < n; ++r) {
    Hit& hit = hits[r];
    if (uint32_t(best_id[r]) != invalid_id) {
      const float inv_det = 1.0f / best_det[r];
      hit.t = best_t[r];
      hit.prim_id = uint32_t(best_id[r]);
      hit.u = AnyHit ? 0.0f : best_v[r] * inv_det;
      hit.v = AnyHit ? 0.0f : best_w[r] * inv_det;
    } else {
      hit.t = __builtin_inff();
      hit.prim_id = invalid_id;
      hit.u = hit.v = 0;
    }
  }
  return true;
}
#endif

#ifdef __AVX512F__
constexpr int packet_lanes = 16;  // one zmm per ray quantity
#else
constexpr int packet_lanes = 8;
#endif

template <int W, class Node>
void trace_packets(const Node* nodes, const TriangleBlock* blocks, const Ray* rays, Hit* hits, size_t n) {
#ifdef __AVX2__
  if constexpr (W == 8) {
    for (size_t i = 0; i < n; i += packet_lanes) {
      const unsigned m = unsigned(n - i < size_t(packet_lanes) ? n - i : size_t(packet_lanes));
      if (trace_packet_lanes<packet_lanes, false>(nodes, blocks, rays + i, hits + i, m)) continue;
      for (unsigned k = 0; k < m; k += 8) trace_packet<W>(nodes, blocks, rays + i + k, hits + i + k, m - k < 8 ? m - k : 8);
    }
    return;
  }
#endif
  for (size_t i = 0; i < n; i += 8) trace_packet<W>(nodes, blocks, rays + i, hits + i, unsigned(n - i < 8 ? n - i : 8));
}

// Occlusion packets: lane packets where the rays agree, single rays otherwise.
template <int W, class Node>
void occlusion_packets(const Node* nodes, const TriangleBlock* blocks, const Ray* rays, Hit* hits, size_t n) {
#ifdef __AVX2__
  if constexpr (W == 8) {
    for (size_t i = 0; i < n; i += packet_lanes) {
      const unsigned m = unsigned(n - i < size_t(packet_lanes) ? n - i : size_t(packet_lanes));
      if (trace_packet_lanes<packet_lanes, true>(nodes, blocks, rays + i, hits + i, m)) continue;
      trace_batch<W, true>(nodes, blocks, rays + i, hits + i, m);
    }
    return;
  }
#endif
  trace_batch<W, true>(nodes, blocks, rays, hits, n);
}

const Table table = {
    &trace_batch<4, false, Bvh4Node>, &trace_batch<4, true, Bvh4Node>, &trace_packets<4, Bvh4Node>,
    &trace_batch<8, false, Bvh8Node>, &trace_batch<8, true, Bvh8Node>, &trace_packets<8, Bvh8Node>,
    &trace_tlas<4, false, Bvh4Node>, &trace_tlas<4, true, Bvh4Node>,
    &trace_tlas<8, false, Bvh8Node>, &trace_tlas<8, true, Bvh8Node>,
    &occlusion_packets<4, Bvh4Node>, &occlusion_packets<8, Bvh8Node>,
};

}  // namespace
}  // namespace kestrel::kernels::KESTREL_ISA_NS
