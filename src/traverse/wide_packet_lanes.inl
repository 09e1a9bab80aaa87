// Lane packets: 8 rays (AVX2) or 16 (AVX-512) in the lanes of every vector, for coherent
// batches, closest and any hit, with the packet's frustum.
// Part of wide_kernels.inl: included inside namespace kestrel::kernels::KESTREL_ISA_NS (an
// anonymous namespace within it), once per instruction set.
#ifdef __AVX2__
// Coherent packets, L rays (8, or 16 with AVX-512) in the lanes of every vector: each child box of
// a node is tested against all rays at once and each triangle of a leaf against all rays at once,
// so the control flow (which children, in which order, which leaves) is decided once per packet.
// A node's eight children are first tested against the packet's frustum (PacketFrustum); where
// the frustum is tight, inner children it enters are taken without per-ray tests (leaves keep
// theirs), otherwise the per-ray tests follow for the children it did not reject.
// Needs rays that agree on their direction signs (near planes) and on the watertight test's
// axis permutation (kx, ky, kz); the caller splits the packet otherwise. Every per-ray
// operation is the single-ray kernel's, lane by lane, so the hits are identical.
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

// The packet's frustum, after Reshetov et al. 2005 and Wald et al. 2007 (interval arithmetic on
// the packet's ray parameters): over the packet's rays, the origin's range, the inverse
// direction's range (one sign per axis) and the smallest tmin. Each child box of a node gets a
// lower bound of every ray's entry distance and an upper bound of every ray's exit distance,
// both from the per-ray kernel's own float operations at the extreme operands: rounding is
// monotone, so fl(fl(b - o) * i) over the ranges is bounded by its values at their corners.
// A child the frustum rejects is rejected by every ray's own test, so skipping the per-ray
// tests for it changes no hit. Needs finite, nonzero inverse directions (else it is off).
struct PacketFrustum {
  bool on = false;
  bool tight = false;  // frustum only, no per-ray box tests
  int rows[3][2];      // bounds rows of the near and far planes per axis
  float near_x[3];     // origin giving the smallest entry (b - o) per axis
  float far_x[3];      // origin giving the largest exit per axis
  float inv_lo[3], inv_hi[3], far_lo[3], far_hi[3];
  float tmin_lo;

  float mid_org[3], mid_inv[3], mid_tmin;  // the packet's middle ray, for the order

  // The middle ray's entry distances into the 8 children (its own slab test's tn).
  vf8 middle_entry(const Bvh8Node& node) const {
    using S = Simd<8>;
    vf8 t = S::splat(mid_tmin);
    for (int a = 0; a < 3; ++a)
      t = vmax((S::load(node.bounds[rows[a][0]]) - mid_org[a]) * mid_inv[a], t);
    return t;
  }

  // Children of `node` that some ray of the packet may enter before max_t: bit j for child
  // j; `lower` gets the entry bound (a valid sort key: no ray enters child j before it).
  unsigned test(const Bvh8Node& node, float max_t, vf8& lower) const {
    using S = Simd<8>;
    vf8 lo = S::splat(tmin_lo), hi = S::splat(max_t);
    for (int a = 0; a < 3; ++a) {
      const vf8 xn = S::load(node.bounds[rows[a][0]]) - near_x[a];
      const vf8 xf = S::load(node.bounds[rows[a][1]]) - far_x[a];
      const vf8 n0 = xn * inv_lo[a], n1 = xn * inv_hi[a];
      const vf8 f0 = xf * far_lo[a], f1 = xf * far_hi[a];
      lo = vmax(n0 < n1 ? n0 : n1, lo);
      hi = vmin(f0 > f1 ? f0 : f1, hi);
    }
    lower = lo;
    return S::mask(lo <= hi);
  }
};

// A frustum is tight (PacketFrustum::tight) where the rays' directions agree within this
// spread (per axis, components over the largest: ~3 degrees) and their origins lie within
// this fraction of the scene's extent. Measured on the shared scenes' camera and shadow rays.
constexpr float tight_spread = 0.05f, tight_extent = 0.01f;

// A packet spends long enough on a node for a prefetch of each child it will visit to pay
// (single rays do not: measured slower there).
inline void prefetch_child(const Bvh8Node* nodes, const TriangleBlock* blocks, uint32_t child) {
  const char* p = child & wide_leaf_bit
                      ? reinterpret_cast<const char*>(blocks + (child & ~wide_leaf_bit))
                      : reinterpret_cast<const char*>(nodes + child);
  for (int line = 0; line < 4; ++line) __builtin_prefetch(p + 64 * line);
}

// Every component of rays[min(l, n - 1)] in lane l at once (c[0..7]: org x y z, dir x y z,
// tmin, tmax): each ray read whole and the rays transposed in registers. Seven gathers of
// single floats had been 14 % of a camera-ray packet's time inside Sponza.
#ifdef __AVX512F__
// The 16 x 8 transpose's permutations (load_lane_rays): element e of an output register takes
// element idx[e] of a pair of input registers (0-15: the first, 16-31: the second).
struct TransposeTables {
  alignas(64) int32_t s1[2][16];  // rays 4q + e / 4, comps 4h + e % 4 (h: the table)
  alignas(64) int32_t s2[4][16];  // rays 8m + e / 2, comps 2p + e % 2 (p: the table)
  alignas(64) int32_t s3[2][16];  // ray e, comp of parity k (k: the table)
};
constexpr TransposeTables make_transpose_tables() {
  TransposeTables t{};
  for (int e = 0; e < 16; ++e) {
    for (int h = 0; h < 2; ++h) {
      const int r = e / 4, comp = 4 * h + e % 4;  // from rays 2j, 2j + 1 per register
      t.s1[h][e] = (r / 2) * 16 + (r % 2) * 8 + comp;
    }
    for (int p = 0; p < 4; ++p) {
      const int r = e / 2, comp = 2 * p + e % 2;  // from rays 4q.. (comps 4h..) per register
      t.s2[p][e] = (r / 4) * 16 + (r % 4) * 4 + comp % 4;
    }
    for (int k = 0; k < 2; ++k) t.s3[k][e] = (e / 8) * 16 + (e % 8) * 2 + k;
  }
  return t;
}
inline constexpr TransposeTables transpose_tables = make_transpose_tables();
#endif
template <int L>
inline void load_lane_rays(const Ray* rays, unsigned n, typename Simd<L>::F c[8]) {
  static_assert(sizeof(Ray) == 8 * sizeof(float));
  const auto ray = [&](unsigned l) { return &rays[l < n ? l : n - 1].org.x; };
#ifdef __AVX512F__
  if constexpr (L == 16) {
    // Stage 0: register j holds rays 2j and 2j + 1. Stage 1: rays 4q..4q+3, comps 0-3 or 4-7.
    // Stage 2: rays 8m..8m+7, comps 2q, 2q+1. Stage 3: one comp of all 16 rays.
    const TransposeTables& tt = transpose_tables;
    const auto index = [](const int32_t* p) { return _mm512_load_si512(p); };
    __m512 a[8], b[8], d[8];
    for (int j = 0; j < 8; ++j)
      a[j] = _mm512_insertf32x8(_mm512_castps256_ps512(_mm256_loadu_ps(ray(2 * j))),
                                _mm256_loadu_ps(ray(2 * j + 1)), 1);
    for (int q = 0; q < 4; ++q)
      for (int h = 0; h < 2; ++h)
        b[2 * q + h] = _mm512_permutex2var_ps(a[2 * q], index(tt.s1[h]), a[2 * q + 1]);
    // b[2q + h]: rays 4q.., comps 4h..; stage 2 pairs quads 2m, 2m + 1 with the same h.
    for (int m = 0; m < 2; ++m)
      for (int p = 0; p < 4; ++p)  // comps 2p, 2p + 1: half h = p / 2
        d[4 * m + p] = _mm512_permutex2var_ps(b[2 * (2 * m) + p / 2], index(tt.s2[p]),
                                              b[2 * (2 * m + 1) + p / 2]);
    for (int comp = 0; comp < 8; ++comp)
      c[comp] = reinterpret_cast<vf16>(
          _mm512_permutex2var_ps(d[comp / 2], index(tt.s3[comp % 2]), d[4 + comp / 2]));
    return;
  }
#endif
  if constexpr (L == 8) {
    __m256 r[8], t[8], u[8];
    for (int j = 0; j < 8; ++j) r[j] = _mm256_loadu_ps(ray(j));
    for (int j = 0; j < 4; ++j) {
      t[2 * j] = _mm256_unpacklo_ps(r[2 * j], r[2 * j + 1]);
      t[2 * j + 1] = _mm256_unpackhi_ps(r[2 * j], r[2 * j + 1]);
    }
    for (int g = 0; g < 2; ++g) {  // rays 4g..4g+3
      u[4 * g + 0] = _mm256_shuffle_ps(t[4 * g], t[4 * g + 2], 0x44);
      u[4 * g + 1] = _mm256_shuffle_ps(t[4 * g], t[4 * g + 2], 0xEE);
      u[4 * g + 2] = _mm256_shuffle_ps(t[4 * g + 1], t[4 * g + 3], 0x44);
      u[4 * g + 3] = _mm256_shuffle_ps(t[4 * g + 1], t[4 * g + 3], 0xEE);
    }
    for (int k = 0; k < 4; ++k) {
      c[k] = reinterpret_cast<vf8>(_mm256_permute2f128_ps(u[k], u[4 + k], 0x20));
      c[4 + k] = reinterpret_cast<vf8>(_mm256_permute2f128_ps(u[k], u[4 + k], 0x31));
    }
  }
}

// What became of a lane packet: traced; or not, because its rays disagree on the near planes
// or the axis permutation (split: the caller splits them by class) or some ray cannot hit
// (untraceable: the caller traces the others and gives it a miss).
enum class PacketOutcome { traced, split, untraceable };

// Whether every lane's ray is traceable (batches.h's is_traceable, lane by lane, on the
// registers load_lane_rays transposed them into): the lane kernels take whole batches
// unscanned, since a separate pass over a batch read its rays from memory twice.
template <int L>
inline bool lanes_traceable(const typename Simd<L>::F comp[8]) {
  using VF = typename Simd<L>::F;
  using VI = typename Simd<L>::I;
  const VF big = Simd<L>::splat(__builtin_inff());
  VI ok = (comp[6] <= comp[7]) & ((comp[3] != VF{}) | (comp[4] != VF{}) | (comp[5] != VF{}));
  for (int c = 0; c < 6; ++c) ok &= (comp[c] < VF{} ? -comp[c] : comp[c]) < big;
  return !Simd<L>::mask(~ok);
}

// The scene's largest extent along an axis, from the root's child boxes (for
// PacketFrustum::tight): once per batch.
inline float scene_extent(const Bvh8Node& root) {
  float scene = 0;
  for (int a = 0; a < 3; ++a) {
    const vf8 lo = Simd<8>::load(root.bounds[2 * a]), hi = Simd<8>::load(root.bounds[2 * a + 1]);
    const float w = -hmin_lanes(-hi)[0] - hmin_lanes(lo)[0];
    scene = w > scene ? w : scene;
  }
  return scene;
}

// The rays of a lane packet as the watertight test needs them (TriRay's, lane by lane).
template <int L>
struct LaneRays {
  typename Simd<L>::F okx, oky, okz, dkx, dky, dkz, sx, sy, tmin;
};

// Triangle i of `blk` against the rays in the lanes, with the single-ray test's operations
// (intersect_block, watertight_hit): the active lanes it hits beyond tmin, with t and the
// edge functions v, w and their sum det (all the rays share the axis permutation kx, ky, kz).
template <int L>
[[gnu::always_inline]] inline typename Simd<L>::I lane_triangle(
    const LaneRays<L>& r, int kx, int ky, int kz, const TriangleBlock& blk, int i,
    typename Simd<L>::I active, typename Simd<L>::F& t, typename Simd<L>::F& v,
    typename Simd<L>::F& w, typename Simd<L>::F& det) {
  using S = Simd<L>;
  using VF = typename S::F;
  using VI = typename S::I;
  const auto bcast = [](float x) { return S::splat(x); };
  const VF zero = {};
  const VF akz = bcast(blk.v[0][kz][i]) - r.okz, bkz = bcast(blk.v[1][kz][i]) - r.okz,
           ckz = bcast(blk.v[2][kz][i]) - r.okz;
  const VF akx = bcast(blk.v[0][kx][i]) - r.okx, aky = bcast(blk.v[0][ky][i]) - r.oky;
  const VF bkx = bcast(blk.v[1][kx][i]) - r.okx, bky = bcast(blk.v[1][ky][i]) - r.oky;
  const VF ckx = bcast(blk.v[2][kx][i]) - r.okx, cky = bcast(blk.v[2][ky][i]) - r.oky;
  const VF ax = akx - r.sx * akz, ay = aky - r.sy * akz;
  const VF bx = bkx - r.sx * bkz, by = bky - r.sy * bkz;
  const VF cx = ckx - r.sx * ckz, cy = cky - r.sy * ckz;
  VF u = cx * by - cy * bx;
  v = ax * cy - ay * cx;
  w = bx * ay - by * ax;
  det = u + v + w;
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
  if (!S::mask(ok)) return ok;
  const VF e10 = bkx - akx, e11 = bky - aky, e12 = bkz - akz;
  const VF e20 = ckx - akx, e21 = cky - aky, e22 = ckz - akz;
  const VF n0 = e11 * e22 - e12 * e21, n1 = e12 * e20 - e10 * e22, n2 = e10 * e21 - e11 * e20;
  const VF ndd = n0 * r.dkx + n1 * r.dky + n2 * r.dkz;
  t = (n0 * akx + n1 * aky + n2 * akz) / ndd;
  return ok & (ndd != zero) & (t > r.tmin);
}

// closer() lane by lane: nearer, or equally near with a smaller id once a hit exists.
template <class VF, class VI>
inline VI closer_lanes(VF t, VI id, VF best_t, VI best_id) {
  return (t < best_t) | ((t == best_t) & (best_id != VI{} - 1) & (id < best_id));
}

// AnyHit: occlusion; a lane leaves the packet at its first hit (t < tmax), children are not
// sorted, and the packet ends when every lane is done. `scene` is scene_extent(nodes[0]).
template <int L, bool AnyHit>
PacketOutcome trace_packet_lanes(const Bvh8Node* nodes, const TriangleBlock* blocks,
                                 const Ray* rays, Hit* hits, unsigned n, float scene) {
  using S = Simd<L>;
  using VF = typename S::F;
  using VI = typename S::I;
  const auto bcast = [](float x) { return S::splat(x); };
  static_assert(sizeof(Ray) == 8 * sizeof(float));
  // The rays in the lanes, component by component (idle lanes repeat the last ray).
  VI lane_index;
  for (int l = 0; l < L; ++l) lane_index[l] = l;
  VF comp[8];
  load_lane_rays<L>(rays, n, comp);
  const VF ox = comp[0], oy = comp[1], oz = comp[2];
  const VF dx = comp[3], dy = comp[4], dz = comp[5];
  const VF tmin = comp[6];
  if (!lanes_traceable<L>(comp)) return PacketOutcome::untraceable;
  // The packet needs one set of near planes and one axis permutation of the watertight test
  // (TriRay::init's, lane by lane): every lane as the first ray, else the caller splits.
  const TriRay tr0(rays[0]);
  const int kx = tr0.kx, ky = tr0.ky, kz = tr0.kz;
  const VF ax = dx < VF{} ? -dx : dx, ay = dy < VF{} ? -dy : dy, az = dz < VF{} ? -dz : dz;
  {
    const VI sign_x = reinterpret_cast<VI>(dx) ^ reinterpret_cast<VI>(bcast(rays[0].dir.x));
    const VI sign_y = reinterpret_cast<VI>(dy) ^ reinterpret_cast<VI>(bcast(rays[0].dir.y));
    const VI sign_z = reinterpret_cast<VI>(dz) ^ reinterpret_cast<VI>(bcast(rays[0].dir.z));
    const VI c1 = ax >= ay, c2 = ax >= az, c3 = ay >= az;
    const VI lane_kz = c1 ? (c2 ? VI{} : VI{} + 2) : (c3 ? VI{} + 1 : VI{} + 2);
    const VF d_kz = kz == 0 ? dx : kz == 1 ? dy : dz;
    const VI swap = d_kz < VF{}, swap0 = VI{} + (tr0.dir[kz] < 0.0f ? -1 : 0);
    if (S::mask((sign_x | sign_y | sign_z) | (lane_kz != kz) | (swap ^ swap0)))
      return PacketOutcome::split;
  }
  const VF dk[3] = {dx, dy, dz}, orgs[3] = {ox, oy, oz};
  const VF dkx = dk[kx], dky = dk[ky], dkz = dk[kz];
  const VF okx = orgs[kx], oky = orgs[ky], okz = orgs[kz];
  const VF sx = dkx / dkz, sy = dky / dkz;  // TriRay's shear, the same division
  const LaneRays<L> lr{okx, oky, okz, dkx, dky, dkz, sx, sy, tmin};
  const VF one = bcast(1.0f), far_factor = bcast(1.00000072f);
  const VF ix = one / dx, iy = one / dy, iz = one / dz;
  const VF fx = ix * far_factor, fy = iy * far_factor, fz = iz * far_factor;  // far_scale
  const VF inf = bcast(__builtin_inff()), zero = {};
  VF best_t = comp[7], best_v = zero, best_w = zero, best_det = bcast(1.0f);
  VI best_id = VI{} - 1;  // invalid_id in every lane
  const VF scale = bcast(0x1p-12f);
  auto cull_of = [&](VF t) { return t + (t < zero ? -t : t) * scale; };
  VF cull =
      AnyHit ? best_t : cull_of(best_t);  // any hit: the ray's own tmax, as the single-ray kernel
  unsigned done = 0;                      // any hit: lanes that found their hit
  const int nrx = __builtin_signbit(rays[0].dir.x) ? 1 : 0,
            nry = 2 + (__builtin_signbit(rays[0].dir.y) ? 1 : 0),
            nrz = 4 + (__builtin_signbit(rays[0].dir.z) ? 1 : 0);
  PacketFrustum fr;
  {
    const int near_rows[3] = {nrx, nry, nrz};
    const VF o[3] = {ox, oy, oz}, inv[3] = {ix, iy, iz}, inv_far[3] = {fx, fy, fz};
    VI bad = (tmin != tmin) | (cull != cull);
    fr.tmin_lo = hmin_lanes(tmin)[0];
    float extent = 0;  // of the origins, largest over the axes
    for (int a = 0; a < 3; ++a) {
      const VF ai = inv[a] < zero ? -inv[a] : inv[a],
               af = inv_far[a] < zero ? -inv_far[a] : inv_far[a];
      bad |= ~((ai > zero) & (ai < inf) & (af < inf)) | (o[a] != o[a]);
      const float olo = hmin_lanes(o[a])[0], ohi = -hmin_lanes(-o[a])[0];
      extent = ohi - olo > extent ? ohi - olo : extent;
      fr.inv_lo[a] = hmin_lanes(inv[a])[0], fr.inv_hi[a] = -hmin_lanes(-inv[a])[0];
      fr.far_lo[a] = hmin_lanes(inv_far[a])[0], fr.far_hi[a] = -hmin_lanes(-inv_far[a])[0];
      const bool positive = (near_rows[a] & 1) == 0;  // entry on the low plane
      fr.rows[a][0] = near_rows[a];
      fr.rows[a][1] = near_rows[a] ^ 1;
      // (b - o) * i grows with b - o where i > 0 and falls where i < 0.
      fr.near_x[a] = positive ? ohi : olo;
      fr.far_x[a] = positive ? olo : ohi;
    }
    fr.on = S::mask(bad) == 0;
    // Frustum only (no per-ray box tests) where the frustum is tight: the directions agree
    // within ~3 degrees (components over the largest, per axis) and the origins lie within
    // 1 % of the scene's extent (the root's box). Otherwise the per-ray tests, with the
    // frustum as a first cull. Either way the same hits; only the work differs.
    if (fr.on) {
      const VF big = vmax(az, vmax(ay, ax));
      float spread = 0;
      for (int a = 0; a < 3; ++a) {
        const VF u = dk[a] / big;
        const float s = -hmin_lanes(-u)[0] - hmin_lanes(u)[0];
        spread = s > spread ? s : spread;
      }
      fr.tight = spread <= tight_spread && extent <= tight_extent * scene;
      const unsigned mid = n / 2;
      for (int a = 0; a < 3; ++a) fr.mid_org[a] = o[a][mid], fr.mid_inv[a] = inv[a][mid];
      fr.mid_tmin = tmin[mid];
    }
  }
  float max_cull = __builtin_inff();  // an upper bound of every lane's cull distance
  auto update_max_cull = [&] { max_cull = -hmin_lanes(-cull)[0]; };
  if (fr.on) update_max_cull();
  struct Entry {
    uint32_t ref, rays;
    float dist;  // no ray of `rays` enters the child before it
    float key;   // the order: nearest first
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
      vf8 lower = {}, key = {};
      unsigned candidates = 0xFF;
      if (fr.on) {
        candidates = fr.test(node, max_cull, lower);
        if (!candidates) goto pop;
        if (!AnyHit && fr.tight) key = fr.middle_entry(node);
      }
      // Any hit pushes unsorted, last slot first, so the slots pop in slot order: largest box
      // first (build_wide_nodes). Measured against the middle ray's nearest-first order:
      // Sponza shadow rays 30.0 against 25.7 Mrays/s, the bunny grid's 3.9 against 3.3.
      while (candidates) {
        const int j = AnyHit ? 31 - __builtin_clz(candidates) : int(ctz(candidates));
        candidates &= ~(1u << j);
        const uint32_t child = node.child[j];
        if (child == wide_empty) continue;
        Entry e;
        if (fr.tight && !(child & wide_leaf_bit)) {
          // An inner child the tight frustum enters: no per-ray test. Its leaves get the
          // per-ray tests that decide which rays test their triangles. Ordered by the
          // packet's middle ray (the frustum's bound orders poorly).
          e = {child, cur_rays, lower[j], key[j]};
        } else {
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
          const float d = AnyHit ? 0.0f : hmin_lanes(select_lanes(hit, tn, inf))[0];
          e = {child, m, d, d};
        }
        prefetch_child(nodes, blocks, child);
        if constexpr (AnyHit) {
          *sp++ = e;
          continue;
        }
        Entry* k = sp++;  // farthest first: the nearest ends on top
        for (; k > base && k[-1].key < e.key; --k) *k = k[-1];
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
          // A block's unused lanes repeat the triangle before them (same id): tested already.
          if (i > 0 && ((blk->prim_id[i] ^ blk->prim_id[i - 1]) & ~block_last_bit) == 0) continue;
          VF t, v, w, det;
          const VI ok = lane_triangle<L>(lr, kx, ky, kz, *blk, i, active, t, v, w, det);
          if (!S::mask(ok)) continue;
          const VI id = VI{} + int(blk->prim_id[i] & ~block_last_bit);
          if constexpr (AnyHit) {
            const VI found = ok & (t < best_t) & (best_id == VI{} - 1);
            const unsigned f = S::mask(found);
            if (!f) continue;
            best_t = select_lanes(found, t, best_t);
            best_id = select_lanes(found, id, best_id);
            done |= f;
            continue;
          }
          const VI better = ok & closer_lanes(t, id, best_t, best_id);
          if (!S::mask(better)) continue;
          best_t = select_lanes(better, t, best_t);
          best_id = select_lanes(better, id, best_id);
          best_v = select_lanes(better, v, best_v);
          best_w = select_lanes(better, w, best_w);
          best_det = select_lanes(better, det, best_det);
        }
        if (blk->prim_id[0] & block_last_bit) break;
      }
      if (!AnyHit) {
        cull = cull_of(best_t);
        if (fr.on) update_max_cull();
      }
    }
  pop:
    while (true) {
      if (sp == stack || (AnyHit && done == (1u << n) - 1)) goto finish;
      --sp;
      // Rays whose best hit may lie beyond the entry's nearest point (any hit: not done).
      // (The per-ray path pushes any-hit entries at distance 0.)
      const unsigned keep = sp->rays & ~done & S::mask(bcast(sp->dist) <= cull);
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
  return PacketOutcome::traced;
}
#endif
