// Single-ray traversal of a wide BVH: the ordered stack (sorting networks on AVX2), closest
// and any hit, and the two-level walk (TLAS leaves enter a BLAS in object space).
// Part of wide_kernels.inl: included inside namespace kestrel::kernels::KESTREL_ISA_NS (an
// anonymous namespace within it), once per instruction set.

// batches.h's is_traceable: the kernels of this file and of the packets take whole batches
// unscanned and give the untraceable rays a miss (a separate pass over a batch read its rays
// from memory twice: ~6 % of tracing camera rays as packets). Here, with internal linkage,
// since an inline function shared with the baseline-ISA callers could be linked from an ISA
// file. (Ray streams take their runs from the scan: wide_stream_lanes.inl.)
inline bool traceable(const Ray& r) {
  const float big = __builtin_inff();
  const float c[6] = {r.org.x, r.org.y, r.org.z, r.dir.x, r.dir.y, r.dir.z};
  bool finite = true;
  for (float v : c) finite &= (v < 0.0f ? -v : v) < big;
  return finite && r.tmin <= r.tmax && (r.dir.x != 0.0f || r.dir.y != 0.0f || r.dir.z != 0.0f);
}

// An untraceable ray's result (the defaults, written field by field: Hit's and InstanceHit's
// implicit constructors are inline functions the linker could share with code for other
// ISAs).
inline void set_miss(Hit& h) {
  h.t = __builtin_inff();
  h.prim_id = invalid_id;
  h.u = h.v = 0;
}
inline void set_miss(InstanceHit& h) {
  h.t = __builtin_inff();
  h.prim_id = h.instance_id = invalid_id;
  h.u = h.v = 0;
}

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
    case 0xAA:
      return _mm256_blend_epi32(lo, hi, 0xAA);
    case 0xCC:
      return _mm256_blend_epi32(lo, hi, 0xCC);
    case 0xF0:
      return _mm256_blend_epi32(lo, hi, 0xF0);
    case 0x66:
      return _mm256_blend_epi32(lo, hi, 0x66);
    case 0x3C:
      return _mm256_blend_epi32(lo, hi, 0x3C);
    default:
      return _mm256_blend_epi32(lo, hi, 0x5A);
  }
}

inline uint32_t push_sorted8(const uint32_t* child, vf8 tnear, vi8 hit, StackEntry*& sp) {
  const __m256i iota = _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7);
  __m256i bits = _mm256_castps_si256(reinterpret_cast<__m256>(tnear));
  // Negative floats: flip the magnitude bits so integer order is float order.
  bits = _mm256_xor_si256(bits, _mm256_srli_epi32(_mm256_srai_epi32(bits, 31), 1));
  __m256i key = _mm256_or_si256(_mm256_andnot_si256(_mm256_set1_epi32(7), bits), iota);
  key = _mm256_blendv_epi8(_mm256_set1_epi32(0x7FFFFFFF), key, reinterpret_cast<__m256i>(hit));
  // The nearest child by a minimum over the keys, off the sort's longer dependency chain:
  // the next node's load can start while the network runs.
  __m256i least = _mm256_min_epi32(key, _mm256_shuffle_epi32(key, 0xB1));
  least = _mm256_min_epi32(least, _mm256_shuffle_epi32(least, 0x4E));
  least = _mm256_min_epi32(least, _mm256_permute2x128_si256(least, least, 1));
  const unsigned nearest = unsigned(_mm256_cvtsi256_si32(least)) & 7u;
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
  const __m256i rev =
      _mm256_and_si256(_mm256_sub_epi32(_mm256_set1_epi32(n - 1), iota), _mm256_set1_epi32(7));
  const __m256i order = _mm256_permutevar8x32_epi32(lane, rev);
  const __m256i refs = _mm256_permutevar8x32_epi32(
      _mm256_loadu_si256(reinterpret_cast<const __m256i*>(child)), order);
  const __m256i dists =
      _mm256_permutevar8x32_epi32(_mm256_castps_si256(reinterpret_cast<__m256>(tnear)), order);
  const __m256i lo = _mm256_unpacklo_epi32(refs, dists), hi = _mm256_unpackhi_epi32(refs, dists);
  _mm256_storeu_si256(reinterpret_cast<__m256i*>(sp), _mm256_permute2x128_si256(lo, hi, 0x20));
  _mm256_storeu_si256(reinterpret_cast<__m256i*>(sp) + 1, _mm256_permute2x128_si256(lo, hi, 0x31));
  sp += n - 1;  // slot n-1 holds the nearest, not part of the stack
  return child[nearest];
}
#endif

// Deepest wide tree: the Bvh2 depth bound (255) with at most W-1 entries pushed per level.
template <int W>
inline constexpr int stack_size = 256 * (W - 1) + 1 + 8;

// Walks a wide BVH nearest child first, from `root` (an inner node the ray's box test reached;
// 0, the tree's root, unless a ray stream hands the ray over below it). leaf(ref) handles a
// leaf reference: it may lower best_t (closest hit) and returns true to stop (any hit). Node
// is Bvh4Node or Bvh8Node.
// Any hit visits a node's children in slot order (largest box first), or with Nearest, as
// closest hit does, nearest first (trace.cpp times both orders).
// Inlined into its caller, where the ray's constants and the hit being kept are locals the
// compiler can tell apart: as a function of its own, every store of a closer hit could alias
// the ray and forced the triangle test to reload it per block (4 % slower on diffuse rays).
template <int W, bool AnyHit, class Node, bool Nearest = false, class LeafFn>
[[gnu::always_inline]] inline void traverse(const Node* nodes, const BoxRay<W>& box, float tmin_s,
                                            float& best_t, LeafFn&& leaf, uint32_t root = 0) {
  using S = Simd<W>;
  using F = typename S::F;
  const F tmin = S::splat(tmin_s);
  float cull_t = AnyHit ? best_t : cull_distance(best_t);
  F tmax = S::splat(cull_t);
  StackEntry stack[stack_size<W>];
  StackEntry* sp = stack;
  uint32_t cur = root;  // an inner node
  while (true) {
    // Descend through inner nodes, nearest child first.
    while (!(cur & wide_leaf_bit)) {
      const Node& node = nodes[cur];
      KSTAT(++stat_nodes);
      F tnear;
      unsigned m = box.test(node.bounds, tmin, tmax, tnear);
      KSTAT(++stat_hist[__builtin_popcount(m)]);
      if (!m) goto pop;
      if constexpr (AnyHit && !Nearest) {
        // Occlusion: no sorting; slot order, which is largest box first (build_wide_nodes).
        // The first hit slot now, the others pushed last first so they pop in slot order.
        cur = node.child[ctz(m)];
        m &= m - 1;
#ifdef __AVX512F__
        if constexpr (W == 8) {
          // The others in one store: compressed in slot order, then reversed.
          if (m) {
            const int n = __builtin_popcount(m);
            const __m512i refs = _mm512_cvtepu32_epi64(
                _mm256_loadu_si256(reinterpret_cast<const __m256i*>(node.child)));  // dist 0
            const __m512i packed = _mm512_maskz_compress_epi64(__mmask8(m), refs);
            const __m512i rev =
                _mm512_and_si512(_mm512_sub_epi64(_mm512_set1_epi64(n - 1),
                                                  _mm512_setr_epi64(0, 1, 2, 3, 4, 5, 6, 7)),
                                 _mm512_set1_epi64(7));
            _mm512_storeu_si512(sp, _mm512_permutexvar_epi64(rev, packed));
            sp += n;
          }
          continue;
        }
#endif
        while (m) {
          const unsigned q = 31u - unsigned(__builtin_clz(m));
          m &= ~(1u << q);
          *sp++ = {node.child[q], 0.0f};
        }
        continue;
      }
      unsigned r = ctz(m);
      m &= m - 1;
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

// A ray's closest hit so far.
struct Closest {
  float t, v, w, det;
  uint32_t id;
};

// Keeps lane i of a test's hits if it is closer (closest hit) or any hit before c.t (any
// hit: returns true). ids: the prim ids of the lanes.
template <bool AnyHit, class Hits>
[[gnu::always_inline]] inline bool take_hits(const Hits& h, const uint32_t* const* ids,
                                             Closest& c) {
  for (unsigned m = h.mask; m; m &= m - 1) {
    const unsigned i = ctz(m);
    const uint32_t id = ids[i >> 2][i & 3] & ~block_last_bit;
    if (AnyHit) {
      if (h.t[i] < c.t) {
        c.t = h.t[i], c.id = id;
        return true;
      }
    } else if (closer(h.t[i], id, c.t, c.id)) {
      c = {h.t[i], h.v[i], h.w[i], h.det[i], id};
    }
  }
  return false;
}

// The blocks of leaf `ref` against one ray; any hit: true at the first hit before c.t. Closest
// hit with AVX2 tests two blocks at a time (a leaf of 5-8 triangles in one test of eight
// lanes); any hit one at a time, so a hit in the first ends the query before the second is
// read (pairs measured equal or slower for occlusion, docs/benchmarks.md).
template <bool AnyHit>
[[gnu::always_inline]] inline bool leaf_ray(const TriangleBlock* blocks, uint32_t ref,
                                            const TriRay& tri, Closest& c) {
  for (const TriangleBlock* blk = blocks + (ref & ~wide_leaf_bit);;) {
#ifdef __AVX2__
    if (!AnyHit && !(blk->prim_id[0] & block_last_bit)) {
      KSTAT(stat_blocks += 2);
      const HitsOf<8> h = intersect_rows<AnyHit>(tri, Rows8{blk});
      const uint32_t* ids[2] = {blk[0].prim_id, blk[1].prim_id};
      if (take_hits<AnyHit>(h, ids, c)) return true;
      if (blk[1].prim_id[0] & block_last_bit) return false;
      blk += 2;
      continue;
    }
#endif
    KSTAT(++stat_blocks);
    const BlockHits h = intersect_block<AnyHit>(tri, *blk);
    const uint32_t* ids[1] = {blk->prim_id};
    if (take_hits<AnyHit>(h, ids, c)) return true;
    if (blk->prim_id[0] & block_last_bit) return false;
    ++blk;
  }
}

// The closest (or any) triangle hit of one ray in one wide BVH (any hit: Nearest as traverse).
template <int W, bool AnyHit, class Node, bool Nearest = false>
inline void trace_ray(const Node* nodes, const TriangleBlock* blocks, const Ray& ray, Hit& hit) {
  const BoxRay<W> box(ray);
  const TriRay tri(ray);
  KSTAT(++stat_rays);
  Closest c = {ray.tmax, 0, 0, 1, invalid_id};
  traverse<W, AnyHit, Node, Nearest>(nodes, box, ray.tmin, c.t, [&](uint32_t ref) {
    return leaf_ray<AnyHit>(blocks, ref, tri, c);
  });
  if (c.id != invalid_id) {
    hit.t = c.t;
    hit.prim_id = c.id;
    if (AnyHit) {
      hit.u = hit.v = 0;
    } else {
      const float inv_det = 1.0f / c.det;
      hit.u = c.v * inv_det;
      hit.v = c.w * inv_det;
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
  out.org = {m[0] * o.x + m[1] * o.y + m[2] * o.z + m[3],
             m[4] * o.x + m[5] * o.y + m[6] * o.z + m[7],
             m[8] * o.x + m[9] * o.y + m[10] * o.z + m[11]};
  out.dir = {m[0] * d.x + m[1] * d.y + m[2] * d.z, m[4] * d.x + m[5] * d.y + m[6] * d.z,
             m[8] * d.x + m[9] * d.y + m[10] * d.z};
  out.tmin = r.tmin;
}

template <int W, bool AnyHit, class Node>
void trace_tlas(const void* tlas_nodes, const InstanceData* instances, const Ray* rays,
                InstanceHit* hits, size_t n, uint32_t ray_mask) {
  const Node* tlas = static_cast<const Node*>(tlas_nodes);
  for (size_t k = 0; k < n; ++k) {
    const Ray& ray = rays[k];
    if (!traceable(ray)) {
      set_miss(hits[k]);
      continue;
    }
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
      if (!AnyHit && !(h.t < best.t || (h.t == best.t && best.instance_id != invalid_id &&
                                        inst.id < best.instance_id)))
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

template <int W, bool AnyHit, class Node, bool Nearest = false>
void trace_batch(const Node* nodes, const TriangleBlock* blocks, const Ray* rays, Hit* hits,
                 size_t n) {
  for (size_t i = 0; i < n; ++i) {
    if (traceable(rays[i]))
      trace_ray<W, AnyHit, Node, Nearest>(nodes, blocks, rays[i], hits[i]);
    else
      set_miss(hits[i]);
  }
}
