// Packets: up to 8 rays walking one traversal order (any ISA), and the dispatch of batches to
// the lane packets (wide_packet_lanes.inl) where the ISA has them.
// Part of wide_kernels.inl: included inside namespace kestrel::kernels::KESTREL_ISA_NS (an
// anonymous namespace within it), once per instruction set.
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
void trace_packet(const Node* nodes, const TriangleBlock* blocks, const Ray* rays, Hit* hits,
                  unsigned n) {
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
        const uint64_t m =
            lane[r].box.test(node.bounds, lane[r].tmin, S::splat(lane[r].cull_t), tn);
        masks |= m << (8 * r);
        dmin = vmin(lane[r].box.test_mask != 0 ? tn : inf, dmin);
      }
      const uint64_t by_child = transpose8x8(masks);  // byte j: rays that hit child j
      unsigned hit_children = 0;
      for (int j = 0; j < W; ++j)
        hit_children |= unsigned((by_child >> (8 * j)) & 0xFF) != 0 ? 1u << j : 0u;
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

// trace(rays, hits, k) on the traceable ones of rays[0..n) (n <= 16), gathered; misses for
// the others.
// (Storage without Ray's and Hit's constructors, as HitStorage; zeroed, since the compiler
// cannot tell that trace() writes the results read back.)
template <class Fn>
void trace_traceable(const Ray* rays, Hit* hits, unsigned n, Fn&& trace) {
  union Storage {
    Ray rays[16];
    Hit hits[16];
    Storage() { __builtin_memset(static_cast<void*>(this), 0, sizeof(*this)); }
  } sub, sub_hits;
  unsigned index[16], k = 0;
  for (unsigned r = 0; r < n; ++r) {
    if (traceable(rays[r])) {
      index[k] = r;
      sub.rays[k++] = rays[r];
    } else {
      set_miss(hits[r]);
    }
  }
  if (k) trace(sub.rays, sub_hits.hits, k);
  for (unsigned i = 0; i < k; ++i) hits[index[i]] = sub_hits.hits[i];
}

// Whether every ray of rays[0..n) is traceable.
inline bool all_traceable(const Ray* rays, unsigned n) {
  bool all = true;
  for (unsigned r = 0; r < n; ++r) all &= traceable(rays[r]);
  return all;
}

#ifdef __AVX512F__
constexpr int packet_lanes = 16;  // one zmm per ray quantity
#else
constexpr int packet_lanes = 8;
#endif

// The rays and result slots of the packet after next: a packet is the first to touch its rays
// (the batch is not scanned ahead), and their misses stood out in its profile.
inline void prefetch_packet(const Ray* rays, Hit* hits, size_t i, size_t n) {
  const size_t ahead = i + 2 * size_t(packet_lanes);
  if (ahead + packet_lanes > n) return;
  const char* r = reinterpret_cast<const char*>(rays + ahead);
  for (size_t b = 0; b < packet_lanes * sizeof(Ray); b += 64) __builtin_prefetch(r + b);
  char* h = reinterpret_cast<char*>(hits + ahead);
  for (size_t b = 0; b < packet_lanes * sizeof(Hit); b += 64) __builtin_prefetch(h + b, 1);
}

#ifdef __AVX2__
// A lane packet's rays must agree on their direction signs and the watertight test's axis
// permutation: where they do not (a packet across the image's centre lines or the diagonals
// where the dominant axis changes), each group of agreeing rays becomes a packet of its own.
// The direction's sign bits (x, y, z): lane_class's first three bits.
inline unsigned direction_signs(const Ray& r) {
  return unsigned(__builtin_signbit(r.dir.x) != 0) |
         unsigned(__builtin_signbit(r.dir.y) != 0) << 1 |
         unsigned(__builtin_signbit(r.dir.z) != 0) << 2;
}
inline unsigned lane_class(const Ray& r) {
  const TriRay t(r);
  return direction_signs(r) | unsigned(t.kz) << 3 | unsigned(t.dir[t.kz] < 0.0f) << 5;
}

template <bool AnyHit>
void trace_lane_packet(const Bvh8Node* nodes, const TriangleBlock* blocks, const Ray* rays,
                       Hit* hits, unsigned n, float scene) {
  const PacketOutcome outcome =
      trace_packet_lanes<packet_lanes, AnyHit>(nodes, blocks, rays, hits, n, scene);
  if (outcome == PacketOutcome::traced) return;
  if (outcome == PacketOutcome::untraceable)
    return trace_traceable(rays, hits, n, [&](const Ray* r, Hit* h, unsigned k) {
      trace_lane_packet<AnyHit>(nodes, blocks, r, h, k, scene);
    });
  unsigned cls[packet_lanes];
  for (unsigned r = 0; r < n; ++r) cls[r] = lane_class(rays[r]);
  Ray sub[packet_lanes];
  Hit sub_hits[packet_lanes];
  unsigned index[packet_lanes];
  for (unsigned left = (1u << n) - 1; left;) {
    const unsigned c = cls[ctz(left)];
    unsigned k = 0;
    for (unsigned rs = left; rs; rs &= rs - 1) {
      const unsigned r = ctz(rs);
      if (cls[r] != c) continue;
      index[k] = r;
      sub[k++] = rays[r];
      left &= ~(1u << r);
    }
    // One class, so it is traced (single rays would give the same hits otherwise).
    if (trace_packet_lanes<packet_lanes, AnyHit>(nodes, blocks, sub, sub_hits, k, scene) !=
        PacketOutcome::traced)
      trace_batch<8, AnyHit>(nodes, blocks, sub, sub_hits, k);
    for (unsigned i = 0; i < k; ++i) hits[index[i]] = sub_hits[i];
  }
}
#endif

template <int W, class Node>
void trace_packets(const Node* nodes, const TriangleBlock* blocks, const Ray* rays, Hit* hits,
                   size_t n) {
#ifdef __AVX2__
  if constexpr (W == 8) {
    const float scene = scene_extent(nodes[0]);
    for (size_t i = 0; i < n; i += packet_lanes) {
      const unsigned m = unsigned(n - i < size_t(packet_lanes) ? n - i : size_t(packet_lanes));
      prefetch_packet(rays, hits, i, n);
      trace_lane_packet<false>(nodes, blocks, rays + i, hits + i, m, scene);
    }
    return;
  }
#endif
  for (size_t i = 0; i < n; i += 8) {
    const unsigned m = unsigned(n - i < 8 ? n - i : 8);
    if (all_traceable(rays + i, m))
      trace_packet<W>(nodes, blocks, rays + i, hits + i, m);
    else
      trace_traceable(rays + i, hits + i, m, [&](const Ray* r, Hit* h, unsigned k) {
        trace_packet<W>(nodes, blocks, r, h, k);
      });
  }
}

// Occlusion packets: lane packets where the rays agree, single rays otherwise.
template <int W, class Node>
void occlusion_packets(const Node* nodes, const TriangleBlock* blocks, const Ray* rays, Hit* hits,
                       size_t n) {
#ifdef __AVX2__
  if constexpr (W == 8) {
    const float scene = scene_extent(nodes[0]);
    for (size_t i = 0; i < n; i += packet_lanes) {
      const unsigned m = unsigned(n - i < size_t(packet_lanes) ? n - i : size_t(packet_lanes));
      prefetch_packet(rays, hits, i, n);
      trace_lane_packet<true>(nodes, blocks, rays + i, hits + i, m, scene);
    }
    return;
  }
#endif
  trace_batch<W, true>(nodes, blocks, rays, hits, n);
}
