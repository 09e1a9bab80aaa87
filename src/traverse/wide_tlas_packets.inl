// Two-level lane packets: coherent rays (camera rays, shadow rays towards one light) through
// the TLAS together, and into each instance's BLAS as a lane packet of their object-space rays.
// Part of wide_kernels.inl: included inside namespace kestrel::kernels::KESTREL_ISA_NS (an
// anonymous namespace within it), once per instruction set, after wide_packets.inl.
//
// The hits are trace_tlas's, lane by lane: every ray tests the TLAS's child boxes with the
// single-ray kernel's operations (BoxRay), enters an instance's BLAS with the same object-space
// ray and tmax, and keeps a hit by the same rule (nearer; equally near in a smaller instance),
// which picks the lexicographically smallest (t, instance, prim) whatever the visiting order.
#ifdef __AVX2__
// Instances a packet enters with fewer rays than this trace them one by one.
constexpr unsigned tlas_packet_min_rays = 4;

// Up to packet_lanes rays that agree on their direction signs (direction_signs); split
// otherwise.
template <bool AnyHit>
PacketOutcome trace_tlas_lanes(const Bvh8Node* tlas, const InstanceData* instances, const Ray* rays,
                               InstanceHit* hits, unsigned n, uint32_t ray_mask) {
  constexpr int L = packet_lanes;
  using S = Simd<L>;
  using VF = typename S::F;
  using VI = typename S::I;
  const auto bcast = [](float x) { return S::splat(x); };
  const unsigned signs = direction_signs(rays[0]);
  for (unsigned r = 1; r < n; ++r)
    if (direction_signs(rays[r]) != signs) return PacketOutcome::split;
  VI lane_index;
  for (int l = 0; l < L; ++l) lane_index[l] = l;
  VF comp[8];
  load_lane_rays<L>(rays, n, comp);
  if (!lanes_traceable<L>(comp)) return PacketOutcome::untraceable;
  const VF ox = comp[0], oy = comp[1], oz = comp[2];
  const VF one = bcast(1.0f), far_factor = bcast(1.00000072f);  // far_scale
  const VF ix = one / comp[3], iy = one / comp[4], iz = one / comp[5];
  const VF fx = ix * far_factor, fy = iy * far_factor, fz = iz * far_factor;
  const VF tmin = comp[6];
  const VF inf = bcast(__builtin_inff());
  const int nrx = __builtin_signbit(rays[0].dir.x) ? 1 : 0,
            nry = 2 + (__builtin_signbit(rays[0].dir.y) ? 1 : 0),
            nrz = 4 + (__builtin_signbit(rays[0].dir.z) ? 1 : 0);
  // Each lane's best hit so far (trace_tlas's `best`), and its cull distance as a vector.
  float best_t[L], best_u[L] = {}, best_v[L] = {};
  uint32_t best_prim[L], best_inst[L];
  for (unsigned r = 0; r < n; ++r)
    best_t[r] = rays[r].tmax, best_prim[r] = best_inst[r] = invalid_id;
  VF cull;
  const auto update_cull = [&] {
    for (unsigned r = 0; r < n; ++r) cull[r] = AnyHit ? best_t[r] : cull_distance(best_t[r]);
    for (int l = int(n); l < L; ++l) cull[l] = cull[n - 1];
  };
  update_cull();
  unsigned done = 0;  // any hit: lanes that found their hit
  struct Entry {
    uint32_t ref, rays;
    float dist;  // the nearest entry of its rays
  };
  Entry stack[stack_size<8>];
  Entry* sp = stack;
  uint32_t cur = 0;
  unsigned cur_rays = (1u << n) - 1;
  Ray sub[L];
  unsigned index[L];
  union SubHits {
    Hit hit[L];
    SubHits() {}
  } sub_hits;
  while (true) {
    if (!(cur & wide_leaf_bit)) {
      const Bvh8Node& node = tlas[cur];
      const VI active = ((VI{} + int(cur_rays)) >> lane_index & 1) != 0;
      Entry* base = sp;
      for (int j = 0; j < 8; ++j) {
        const uint32_t child = node.child[j];
        if (child == wide_empty) continue;
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
        const Entry e{child, m, AnyHit ? 0.0f : hmin_lanes(select_lanes(hit, tn, inf))[0]};
        Entry* k = sp++;  // farthest first: the nearest ends on top (any hit: slot order)
        if (!AnyHit)
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
      // An instance: its rays in object space, each with trace_tlas's tmax.
      const InstanceData& inst = instances[cur & ~wide_leaf_bit];
      if (inst.mask & ray_mask) {
        unsigned k = 0;
        for (unsigned rs = cur_rays; rs; rs &= rs - 1) {
          const unsigned r = ctz(rs);
          Ray& local = sub[k];
          local = rays[r];
          to_object(inst.world_to_object, rays[r], local);
          if (local.dir.x == 0.0f && local.dir.y == 0.0f && local.dir.z == 0.0f) continue;
          local.tmax = AnyHit ? best_t[r] : __builtin_nextafterf(best_t[r], __builtin_inff());
          index[k++] = r;
        }
        const Bvh8Node* blas = static_cast<const Bvh8Node*>(inst.nodes);
        if (k >= tlas_packet_min_rays)
          trace_lane_packet<AnyHit>(blas, inst.blocks, sub, sub_hits.hit, k, scene_extent(blas[0]));
        else
          for (unsigned i = 0; i < k; ++i)
            trace_ray<8, AnyHit>(blas, inst.blocks, sub[i], sub_hits.hit[i]);
        bool found = false;
        for (unsigned i = 0; i < k; ++i) {
          const Hit& h = sub_hits.hit[i];
          const unsigned r = index[i];
          if (h.prim_id == invalid_id) continue;
          if (!AnyHit && !(h.t < best_t[r] || (h.t == best_t[r] && best_inst[r] != invalid_id &&
                                               inst.id < best_inst[r])))
            continue;
          best_t[r] = h.t, best_prim[r] = h.prim_id, best_inst[r] = inst.id;
          best_u[r] = h.u, best_v[r] = h.v;
          found = true;
          if (AnyHit) done |= 1u << r;
        }
        if (found && !AnyHit) update_cull();
      }
    }
  pop:
    while (true) {
      if (sp == stack || (AnyHit && done == (1u << n) - 1)) goto finish;
      --sp;
      // Rays whose best hit may lie beyond the entry's nearest point (any hit: not done).
      const unsigned keep = sp->rays & ~done & (AnyHit ? ~0u : S::mask(bcast(sp->dist) <= cull));
      if (keep) {
        cur = sp->ref;
        cur_rays = keep;
        break;
      }
    }
  }
finish:
  for (unsigned r = 0; r < n; ++r) {
    InstanceHit& h = hits[r];
    const bool hit = best_inst[r] != invalid_id;
    h.t = hit ? best_t[r] : __builtin_inff();
    h.prim_id = best_prim[r];
    h.instance_id = best_inst[r];
    h.u = hit ? best_u[r] : 0.0f;
    h.v = hit ? best_v[r] : 0.0f;
  }
  return PacketOutcome::traced;
}
#endif

// TlasFn: lane packets where the rays agree on their direction signs, single rays otherwise.
template <bool AnyHit>
void trace_tlas_packets(const void* tlas_nodes, const InstanceData* instances, const Ray* rays,
                        InstanceHit* hits, size_t n, uint32_t ray_mask) {
#ifdef __AVX2__
  const Bvh8Node* tlas = static_cast<const Bvh8Node*>(tlas_nodes);
  for (size_t i = 0; i < n; i += packet_lanes) {
    const unsigned m = unsigned(n - i < size_t(packet_lanes) ? n - i : size_t(packet_lanes));
    // Split packets, and those with an untraceable ray, go as single rays (which give it a
    // miss).
    if (trace_tlas_lanes<AnyHit>(tlas, instances, rays + i, hits + i, m, ray_mask) !=
        PacketOutcome::traced)
      trace_tlas<8, AnyHit, Bvh8Node>(tlas_nodes, instances, rays + i, hits + i, m, ray_mask);
  }
#else
  trace_tlas<8, AnyHit, Bvh8Node>(tlas_nodes, instances, rays, hits, n, ray_mask);
#endif
}
