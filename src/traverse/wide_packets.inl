// Packets: up to 8 rays walking one traversal order (any ISA), and lane packets of 8 / 16
// rays in vector lanes (AVX2 / AVX-512) for coherent batches, closest and any hit.
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

#ifdef __AVX2__
// Coherent packets, L rays (8, or 16 with AVX-512) in the lanes of every vector: each child box of
// a node is tested against all rays at once and each triangle of a leaf against all rays at once,
// so the control flow (which children, in which order, which leaves) is decided once per packet.
// Needs rays that agree on their direction signs (near planes) and on the watertight test's
// axis permutation (kx, ky, kz); the caller falls back otherwise. Every per-ray operation is
// the single-ray kernel's, lane by lane, so the hits are identical.
template <class V, class M>
inline V select_lanes(M m, V a, V b) {
  return m != M{} ? a : b;
}

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
  return vmin(d,
              __builtin_shufflevector(d, d, 1, 0, 3, 2, 5, 4, 7, 6, 9, 8, 11, 10, 13, 12, 15, 14));
}

// AnyHit: occlusion; a lane leaves the packet at its first hit (t < tmax), children are not
// sorted, and the packet ends when every lane is done.
template <int L, bool AnyHit>
bool trace_packet_lanes(const Bvh8Node* nodes, const TriangleBlock* blocks, const Ray* rays,
                        Hit* hits, unsigned n) {
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
  alignas(64) float o[3][L], inv[3][L], inv_far[3][L], tmin_a[L], tmax_a[L], sx_a[L], sy_a[L],
      okx_a[L], oky_a[L], okz_a[L], dkx_a[L], dky_a[L], dkz_a[L];
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
  VF cull =
      AnyHit ? best_t : cull_of(best_t);  // any hit: the ray's own tmax, as the single-ray kernel
  unsigned done = 0;                      // any hit: lanes that found their hit
  const int nrx = __builtin_signbit(rays[0].dir.x) ? 1 : 0,
            nry = 2 + (__builtin_signbit(rays[0].dir.y) ? 1 : 0),
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
        const VF nx = (bcast(node.bounds[nrx][j]) - ox) * ix,
                 ny = (bcast(node.bounds[nry][j]) - oy) * iy,
                 nz = (bcast(node.bounds[nrz][j]) - oz) * iz;
        const VF gx = (bcast(node.bounds[nrx ^ 1][j]) - ox) * fx,
                 gy = (bcast(node.bounds[nry ^ 1][j]) - oy) * fy,
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
          const VF akz = bcast(blk->v[0][kz][i]) - okz, bkz = bcast(blk->v[1][kz][i]) - okz,
                   ckz = bcast(blk->v[2][kz][i]) - okz;
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
            const VI ui = reinterpret_cast<VI>(u), vi = reinterpret_cast<VI>(v),
                     wi = reinterpret_cast<VI>(w);
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
          const VF n0 = e11 * e22 - e12 * e21, n1 = e12 * e20 - e10 * e22,
                   n2 = e10 * e21 - e11 * e20;
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
          const VI better =
              ok & (ndd != zero) & (t > tmin) &
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
void trace_packets(const Node* nodes, const TriangleBlock* blocks, const Ray* rays, Hit* hits,
                   size_t n) {
#ifdef __AVX2__
  if constexpr (W == 8) {
    for (size_t i = 0; i < n; i += packet_lanes) {
      const unsigned m = unsigned(n - i < size_t(packet_lanes) ? n - i : size_t(packet_lanes));
      if (trace_packet_lanes<packet_lanes, false>(nodes, blocks, rays + i, hits + i, m)) continue;
      for (unsigned k = 0; k < m; k += 8)
        trace_packet<W>(nodes, blocks, rays + i + k, hits + i + k, m - k < 8 ? m - k : 8);
    }
    return;
  }
#endif
  for (size_t i = 0; i < n; i += 8)
    trace_packet<W>(nodes, blocks, rays + i, hits + i, unsigned(n - i < 8 ? n - i : 8));
}

// Occlusion packets: lane packets where the rays agree, single rays otherwise.
template <int W, class Node>
void occlusion_packets(const Node* nodes, const TriangleBlock* blocks, const Ray* rays, Hit* hits,
                       size_t n) {
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
