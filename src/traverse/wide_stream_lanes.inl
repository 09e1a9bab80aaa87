// Ray streams: a large batch of incoherent rays walks the tree together, the rays in the
// vector lanes and the tree's nodes fetched once per stream (after Barringer & Akenine-Möller
// 2014, "Dynamic ray stream traversal", and Fuetterling et al. 2015). Closest and any hit.
// Part of wide_kernels.inl: included inside namespace kestrel::kernels::KESTREL_ISA_NS (an
// anonymous namespace within it), once per instruction set.
#ifdef __AVX2__
// How it goes. The batch's rays are grouped by lane_class (direction signs and the watertight
// test's axis permutation: one set of near planes per group). Each group is one stream: a
// stack of (node, list of rays) entries, the root first with every ray. At an inner node,
// each chunk of L rays of its list is tested against every child box at once (the single-ray
// kernel's box test, lane by lane), and each child gets the list of rays that enter it; the
// children are pushed farthest first as seen by the list's middle ray. At a leaf, each chunk of
// L rays is tested against each of its triangles at once (lane_triangle: the single-ray
// kernel's triangle test, lane by lane). A list shorter than stream_handover rays goes on as
// single rays from its node (the lanes would idle), and so does everything left of a stream
// whose buffers cannot grow (out of memory: slower, never wrong).
// Every ray is tested against exactly the boxes its own traversal could reach (a subset of the
// stream's) with the same operations, and closest-hit ties resolve to the smallest id, so the
// hits are the single-ray kernel's.
constexpr unsigned stream_handover = 8;

// One thread's buffers, kept between calls (no fresh pages per batch). Null where memory runs
// out (the callers then trace single rays).
struct StreamScratch {
  void* p[4] = {};
  size_t bytes[4] = {};
  // Buffer k with room for `n` bytes (its contents are not kept when it grows).
  void* get(int k, size_t n) {
    if (bytes[k] < n) {
      free(p[k]);
      n += n / 2;
      p[k] = malloc(n);
      bytes[k] = p[k] ? n : 0;
    }
    return p[k];
  }
  // Buffer k grown to `n` bytes, its first `keep` bytes kept; null (the old buffer kept) when
  // there is no memory for it.
  void* grow(int k, size_t n, size_t keep) {
    if (bytes[k] >= n) return p[k];
    n += n / 2;
    void* q = malloc(n);
    if (!q) return nullptr;
    if (keep) __builtin_memcpy(q, p[k], keep);
    free(p[k]);
    p[k] = q;
    bytes[k] = n;
    return q;
  }
  ~StreamScratch() {
    for (void* q : p) free(q);
  }
};

// base[index[l]] in lane l (the masked forms with a zero source: the plain ones start from an
// undefined register).
template <int L>
inline typename Simd<L>::F gather_floats(const float* base, typename Simd<L>::I index) {
#ifdef __AVX512F__
  if constexpr (L == 16)
    return reinterpret_cast<vf16>(_mm512_mask_i32gather_ps(_mm512_setzero_ps(), __mmask16(0xFFFF),
                                                           reinterpret_cast<__m512i>(index), base,
                                                           sizeof(float)));
  else
#endif
    return reinterpret_cast<vf8>(
        _mm256_mask_i32gather_ps(_mm256_setzero_ps(), base, reinterpret_cast<__m256i>(index),
                                 _mm256_castsi256_ps(_mm256_set1_epi32(-1)), sizeof(float)));
}

// Writes the lanes of `ids` selected by `mask` to dst[0..popcount), in lane order; may write
// up to L entries (the buffers have that much room past every list).
template <int L>
inline unsigned compress_ids(uint32_t* dst, typename Simd<L>::I ids, unsigned mask) {
#ifdef __AVX512F__
  if constexpr (L == 16) {
    // Compressed in a register and stored whole (a compressing store is slow on some cores).
    _mm512_storeu_si512(
        dst, _mm512_maskz_compress_epi32(__mmask16(mask), reinterpret_cast<__m512i>(ids)));
    return unsigned(__builtin_popcount(mask));
  }
#endif
  unsigned k = 0;
  for (; mask; mask &= mask - 1) dst[k++] = uint32_t(ids[ctz(mask)]);
  return k;
}

// The stream's rays, by position in the class order, one array per quantity (gathered by lane).
struct StreamRays {
  float *ox, *oy, *oz, *dx, *dy, *dz, *ix, *iy, *iz, *tmin, *cull;
  float *best_t, *best_v, *best_w, *best_det;
  uint32_t* best_id;
  const uint32_t* caller;  // position -> index in the batch
  Closest get(uint32_t p) const {
    return {best_t[p], best_v[p], best_w[p], best_det[p], best_id[p]};
  }
  // The ray's hit so far, and the distance its box tests cull at: closest hit, the hit's
  // cull_distance; any hit, the ray's tmax until it has a hit, then -inf (it is done).
  template <bool AnyHit>
  void set(uint32_t p, const Closest& c) const {
    best_t[p] = c.t, best_v[p] = c.v, best_w[p] = c.w, best_det[p] = c.det, best_id[p] = c.id;
    cull[p] = !AnyHit ? cull_distance(c.t) : c.id != invalid_id ? -__builtin_inff() : c.t;
  }
};

// Leaf lists of fewer rays test their blocks ray by ray.
constexpr unsigned stream_leaf_lanes = 4;

// One group of rays with one lane_class: positions [first, first + m). AnyHit: occlusion; a
// ray leaves every list once it has a hit (its cull distance becomes -inf), children are
// visited in slot order (largest box first) as by single rays.
template <int L, bool AnyHit>
void trace_stream_group(const Bvh8Node* nodes, const TriangleBlock* blocks, const Ray* rays,
                        const StreamRays& s, uint32_t first, uint32_t m, StreamScratch& scratch) {
  using S = Simd<L>;
  using VF = typename S::F;
  using VI = typename S::I;
  const Ray& r0 = rays[s.caller[first]];
  const int nrx = __builtin_signbit(r0.dir.x) ? 1 : 0,
            nry = 2 + (__builtin_signbit(r0.dir.y) ? 1 : 0),
            nrz = 4 + (__builtin_signbit(r0.dir.z) ? 1 : 0);
  const TriRay tr0(r0);
  const int kx = tr0.kx, ky = tr0.ky, kz = tr0.kz;
  const float* const o_all[3] = {s.ox, s.oy, s.oz};
  const float* const d_all[3] = {s.dx, s.dy, s.dz};
  const float* const o_k[3] = {o_all[kx], o_all[ky], o_all[kz]};
  const float* const d_k[3] = {d_all[kx], d_all[ky], d_all[kz]};
  struct Entry {
    uint32_t ref, begin, count;
  };
  // Ray p from node (or leaf) `ref` on as a single ray.
  const auto single = [&](uint32_t p, uint32_t ref) {
    if (AnyHit && s.best_id[p] != invalid_id) return;
    const Ray& ray = rays[s.caller[p]];
    const TriRay tri(ray);
    Closest c = s.get(p);
    if (ref & wide_leaf_bit) {
      leaf_ray<AnyHit>(blocks, ref, tri, c);
    } else {
      const BoxRay<8> box(ray);
      traverse<8, AnyHit>(
          nodes, box, ray.tmin, c.t,
          [&](uint32_t r) { return leaf_ray<AnyHit>(blocks, r, tri, c); }, ref);
    }
    s.template set<AnyHit>(p, c);
  };
  Entry stack[stack_size<8>];
  Entry* sp = stack;
  // ids: the lists of the stack's entries, in stack order (the top entry's list last);
  // children: a node's children's lists while they are made, child j's from j * (count + L).
  size_t ids_cap = size_t(m) * 4 + L;
  uint32_t* ids = static_cast<uint32_t*>(scratch.get(0, ids_cap * sizeof(uint32_t)));
  uint32_t* children = static_cast<uint32_t*>(scratch.get(1, size_t(m + L) * 8 * sizeof(uint32_t)));
  if (!ids || !children) {
    for (uint32_t p = first; p < first + m; ++p) single(p, 0);
    return;
  }
  bool singles = false;  // out of memory: the rest as single rays
  for (uint32_t k = 0; k < m; ++k) ids[k] = first + k;
  Entry cur{0, 0, m};
  size_t top = m;  // ids in use
  VI lane_index;
  for (int l = 0; l < L; ++l) lane_index[l] = l;
  const VF far_factor = S::splat(1.00000072f);  // far_scale
  while (true) {
    const uint32_t* list = ids + cur.begin;
    if (cur.count < stream_handover || singles) {
      // Single rays from here on (from this node, or this leaf's blocks).
      for (uint32_t k = 0; k < cur.count; ++k) single(list[k], cur.ref);
    } else if (cur.ref & wide_leaf_bit) {
      if (cur.count < stream_leaf_lanes) {
        for (uint32_t k = 0; k < cur.count; ++k) single(list[k], cur.ref);
      } else {
        const TriangleBlock* leaf = blocks + (cur.ref & ~wide_leaf_bit);
        for (uint32_t i = 0; i < cur.count; i += L) {
          VI raw;
          __builtin_memcpy(&raw, list + i, sizeof(raw));  // unaligned
          const VI active = lane_index < VI{} + int(cur.count - i);
          const VI id = active ? raw : VI{} + int(list[i]);
          const VF dkz = gather_floats<L>(d_k[2], id);
          LaneRays<L> lr;
          lr.okx = gather_floats<L>(o_k[0], id), lr.oky = gather_floats<L>(o_k[1], id);
          lr.okz = gather_floats<L>(o_k[2], id);
          lr.dkx = gather_floats<L>(d_k[0], id), lr.dky = gather_floats<L>(d_k[1], id);
          lr.dkz = dkz;
          lr.sx = lr.dkx / dkz, lr.sy = lr.dky / dkz;  // TriRay's shear, the same division
          lr.tmin = gather_floats<L>(s.tmin, id);
          VF bt = gather_floats<L>(s.best_t, id), bv = {}, bw = {}, bd = {};
          VI bid =
              reinterpret_cast<VI>(gather_floats<L>(reinterpret_cast<const float*>(s.best_id), id));
          unsigned changed = 0;
          for (const TriangleBlock* blk = leaf;; ++blk) {
            for (int q = 0; q < 4; ++q) {
              // A block's unused lanes repeat the triangle before them (same id).
              if (q > 0 && ((blk->prim_id[q] ^ blk->prim_id[q - 1]) & ~block_last_bit) == 0)
                continue;
              VF t, v, w, det;
              const VI ok = lane_triangle<L>(lr, kx, ky, kz, *blk, q, active, t, v, w, det);
              if (!S::mask(ok)) continue;
              const VI tid = VI{} + int(blk->prim_id[q] & ~block_last_bit);
              const VI better =
                  AnyHit ? ok & (t < bt) & (bid == VI{} - 1) : ok & closer_lanes(t, tid, bt, bid);
              const unsigned b = S::mask(better);
              if (!b) continue;
              changed |= b;
              bt = select_lanes(better, t, bt);
              bid = select_lanes(better, tid, bid);
              bv = select_lanes(better, v, bv);
              bw = select_lanes(better, w, bw);
              bd = select_lanes(better, det, bd);
            }
            if (blk->prim_id[0] & block_last_bit) break;
          }
          for (; changed; changed &= changed - 1) {
            const unsigned l = ctz(changed);
            s.template set<AnyHit>(uint32_t(id[l]), {bt[l], bv[l], bw[l], bd[l], uint32_t(bid[l])});
          }
        }
      }
    } else {
      const Bvh8Node& node = nodes[cur.ref];
      int kids[8], nk = 0;
      for (int j = 0; j < 8; ++j)
        if (node.child[j] != wide_empty) kids[nk++] = j;
      uint32_t count[8] = {};
      const uint32_t n = cur.count;
      const size_t stride = n + L;
      for (uint32_t i = 0; i < n; i += L) {
        VI raw;
        __builtin_memcpy(&raw, list + i, sizeof(raw));  // unaligned
        const VI active = lane_index < VI{} + int(n - i);
        const VI id = active ? raw : VI{} + int(list[i]);
        const VF ox = gather_floats<L>(s.ox, id), oy = gather_floats<L>(s.oy, id),
                 oz = gather_floats<L>(s.oz, id);
        const VF ix = gather_floats<L>(s.ix, id), iy = gather_floats<L>(s.iy, id),
                 iz = gather_floats<L>(s.iz, id);
        const VF tmin = gather_floats<L>(s.tmin, id), cull = gather_floats<L>(s.cull, id);
        const VF fx = ix * far_factor, fy = iy * far_factor, fz = iz * far_factor;
        const unsigned live = S::mask(active);
        for (int q = 0; q < nk; ++q) {
          const int j = kids[q];
          const VF nx = (S::splat(node.bounds[nrx][j]) - ox) * ix,
                   ny = (S::splat(node.bounds[nry][j]) - oy) * iy,
                   nz = (S::splat(node.bounds[nrz][j]) - oz) * iz;
          const VF gx = (S::splat(node.bounds[nrx ^ 1][j]) - ox) * fx,
                   gy = (S::splat(node.bounds[nry ^ 1][j]) - oy) * fy,
                   gz = (S::splat(node.bounds[nrz ^ 1][j]) - oz) * fz;
          const VF tn = vmax(nz, vmax(ny, vmax(nx, tmin)));
          const VF tf = vmin(gz, vmin(gy, vmin(gx, cull)));
          const unsigned hit = S::mask(tn <= tf) & live;
          if (hit) count[j] += compress_ids<L>(children + j * stride + count[j], id, hit);
        }
      }
      // Closest hit: farthest first by the list's middle ray's entry distances (its own slab
      // test's). Any hit: the last slot first, so the slots pop in slot order.
      float key[8];
      if (AnyHit) {
        for (int j = 0; j < 8; ++j) key[j] = float(j);
      } else {
        const uint32_t p = list[n / 2];
        using S8 = Simd<8>;
        vf8 t = S8::load(node.bounds[nrx]) - s.ox[p];
        t = t * s.ix[p];
        vf8 ty = (S8::load(node.bounds[nry]) - s.oy[p]) * s.iy[p];
        vf8 tz = (S8::load(node.bounds[nrz]) - s.oz[p]) * s.iz[p];
        t = vmax(tz, vmax(ty, t));
        for (int j = 0; j < 8; ++j) key[j] = t[j] == t[j] ? t[j] : 0.0f;
      }
      int order[8], no = 0;
      for (int q = 0; q < nk; ++q) {
        const int j = kids[q];
        if (!count[j]) continue;
        int k = no++;
        for (; k > 0 && key[order[k - 1]] < key[j]; --k) order[k] = order[k - 1];
        order[k] = j;
      }
      top = cur.begin;  // this node's list is done with
      size_t need = top + L;
      for (int q = 0; q < no; ++q) need += count[order[q]];
      if (need > ids_cap) {
        void* grown = scratch.grow(0, need * sizeof(uint32_t), top * sizeof(uint32_t));
        if (!grown) {
          // This node's rays from the node on as single rays (its list is still in place:
          // nothing was written over it), and every entry left on the stack after them.
          for (uint32_t k = 0; k < n; ++k) single(list[k], cur.ref);
          singles = true;
          if (sp == stack) return;
          cur = *--sp;
          continue;
        }
        ids = static_cast<uint32_t*>(grown);
        ids_cap = scratch.bytes[0] / sizeof(uint32_t);
      }
      for (int q = 0; q < no; ++q) {
        const int j = order[q];
        __builtin_memcpy(ids + top, children + j * stride, count[j] * sizeof(uint32_t));
        *sp++ = {node.child[j], uint32_t(top), count[j]};
        top += count[j];
      }
    }
    if (sp == stack) return;
    cur = *--sp;
  }
}

// Closest (or any) hits of a batch of traceable rays as ray streams.
template <int L, bool AnyHit>
void trace_stream_lanes(const Bvh8Node* nodes, const TriangleBlock* blocks, const Ray* rays,
                        Hit* hits, size_t n) {
  static thread_local StreamScratch scratch;
  // 15 float arrays and two of ids, each with room for a vector load past its end.
  const size_t stride = n + 16;
  uint8_t* cls = static_cast<uint8_t*>(scratch.get(2, n));
  char* mem = static_cast<char*>(scratch.get(3, stride * 17 * sizeof(float)));
  if (!cls || !mem) return trace_batch<8, AnyHit>(nodes, blocks, rays, hits, n);  // no memory
  // Positions in class order (a counting sort, stable).
  uint32_t start[65] = {};
  for (size_t i = 0; i < n; ++i) {
    cls[i] = uint8_t(lane_class(rays[i]));
    ++start[cls[i] + 1];
  }
  for (int c = 0; c < 64; ++c) start[c + 1] += start[c];
  float* f = reinterpret_cast<float*>(mem);
  StreamRays s;
  float** soa[15] = {&s.ox, &s.oy,   &s.oz,   &s.dx,     &s.dy,     &s.dz,     &s.ix,      &s.iy,
                     &s.iz, &s.tmin, &s.cull, &s.best_t, &s.best_v, &s.best_w, &s.best_det};
  for (int k = 0; k < 15; ++k) *soa[k] = f + k * stride;
  s.best_id = reinterpret_cast<uint32_t*>(f + 15 * stride);
  uint32_t* caller = reinterpret_cast<uint32_t*>(f + 16 * stride);
  s.caller = caller;
  {
    uint32_t at[64];
    for (int c = 0; c < 64; ++c) at[c] = start[c];
    for (size_t i = 0; i < n; ++i) caller[at[cls[i]]++] = uint32_t(i);
  }
  for (size_t p = 0; p < n; ++p) {
    const Ray& r = rays[caller[p]];
    s.ox[p] = r.org.x, s.oy[p] = r.org.y, s.oz[p] = r.org.z;
    s.dx[p] = r.dir.x, s.dy[p] = r.dir.y, s.dz[p] = r.dir.z;
    s.ix[p] = 1.0f / r.dir.x, s.iy[p] = 1.0f / r.dir.y, s.iz[p] = 1.0f / r.dir.z;
    s.tmin[p] = r.tmin;
    s.template set<AnyHit>(uint32_t(p), {r.tmax, 0.0f, 0.0f, 1.0f, invalid_id});
  }
  for (int c = 0; c < 64; ++c)
    if (start[c + 1] > start[c])
      trace_stream_group<L, AnyHit>(nodes, blocks, rays, s, start[c], start[c + 1] - start[c],
                                    scratch);
  for (size_t p = 0; p < n; ++p) {
    const Closest c = s.get(uint32_t(p));
    Hit& hit = hits[caller[p]];
    if (c.id != invalid_id) {
      const float inv_det = 1.0f / c.det;
      hit.t = c.t;
      hit.prim_id = c.id;
      hit.u = AnyHit ? 0.0f : c.v * inv_det;
      hit.v = AnyHit ? 0.0f : c.w * inv_det;
    } else {
      hit.t = __builtin_inff();
      hit.prim_id = invalid_id;
      hit.u = hit.v = 0;
    }
  }
}
#endif

// The stream kernel where the ISA has lanes, single rays otherwise.
template <int W, bool AnyHit, class Node>
void trace_streams(const Node* nodes, const TriangleBlock* blocks, const Ray* rays, Hit* hits,
                   size_t n) {
#ifdef __AVX2__
  if constexpr (W == 8) {
    trace_stream_lanes<packet_lanes, AnyHit>(nodes, blocks, rays, hits, n);
    return;
  }
#endif
  trace_batch<W, AnyHit>(nodes, blocks, rays, hits, n);
}
