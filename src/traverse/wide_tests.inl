// SIMD types and the tests of one ray: W boxes at once (slabs, as SlabRay) and a block of
// four triangles (watertight, as watertight_hit, with its double-precision retry).
// Part of wide_kernels.inl: included inside namespace kestrel::kernels::KESTREL_ISA_NS (an
// anonymous namespace within it), once per instruction set.
typedef float vf4 __attribute__((vector_size(16)));
typedef int32_t vi4 __attribute__((vector_size(16)));
typedef float vf8 __attribute__((vector_size(32)));
typedef int32_t vi8 __attribute__((vector_size(32)));
// Unaligned views for loads (nodes and blocks are aligned, but a plain load costs nothing).
typedef float vf4u __attribute__((vector_size(16), aligned(4)));
typedef float vf8u __attribute__((vector_size(32), aligned(4)));

template <int W>
struct Simd;
template <>
struct Simd<4> {
  using F = vf4;
  using I = vi4;
  static F load(const float* p) { return *reinterpret_cast<const vf4u*>(p); }
  static F splat(float x) { return F{x, x, x, x}; }
  static unsigned mask(I m) { return unsigned(_mm_movemask_ps(reinterpret_cast<__m128>(m))); }
};
template <>
struct Simd<8> {
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
template <>
struct Simd<16> {
  using F = vf16;
  using I = vi16;
  static F load(const float* p) { return *reinterpret_cast<const vf16u*>(p); }
#ifdef __AVX512F__
  // A broadcast: -0 stays -0 (F{} + x would make it +0).
  static F splat(float x) {
    return reinterpret_cast<F>(_mm512_set1_ps(x));
  }
#else
  static F splat(float x) {
    return F{} + x;
  }
#endif
  static unsigned mask(I m) {
#ifdef __AVX512F__
    return unsigned(_mm512_cmplt_epi32_mask(reinterpret_cast<__m512i>(m), _mm512_setzero_si512()));
#else
    const vi8 lo = __builtin_shufflevector(m, m, 0, 1, 2, 3, 4, 5, 6, 7),
              hi = __builtin_shufflevector(m, m, 8, 9, 10, 11, 12, 13, 14, 15);
    return Simd<8>::mask(lo) | Simd<8>::mask(hi) << 8;
#endif
  }
};

// Same semantics as SlabRay::max_keep / min_keep: a NaN candidate keeps the accumulator.
template <class F>
inline F vmax(F candidate, F acc) {
  return candidate > acc ? candidate : acc;
}
template <class F>
inline F vmin(F candidate, F acc) {
  return candidate < acc ? candidate : acc;
}

inline unsigned ctz(unsigned m) {
  return unsigned(__builtin_ctz(m));
}

// As cull_distance in traverse_bvh2.h.
inline float cull_distance(float t) {
  return t + __builtin_fabsf(t) * 0x1p-12f;
}

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
    const float ax = __builtin_fabsf(dir[0]), ay = __builtin_fabsf(dir[1]),
                az = __builtin_fabsf(dir[2]);
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

// The vertex rows of the triangles tested at once: one block (4 lanes), or with AVX2 two
// consecutive blocks of a leaf side by side (8 lanes, `Rows8`). row(k, off) is vertex k's
// row at float offset off (axis * 4) of each block.
struct Rows4 {
  static constexpr int lanes = 4;
  const TriangleBlock* blk;
  vf4 row(int k, int off) const { return Simd<4>::load(&blk->v[k][0][0] + off); }
};
#ifdef __AVX2__
struct Rows8 {
  static constexpr int lanes = 8;
  const TriangleBlock* blk;  // blk[0] and blk[1]
  vf8 row(int k, int off) const {
    const vf4 lo = Simd<4>::load(&blk[0].v[k][0][0] + off),
              hi = Simd<4>::load(&blk[1].v[k][0][0] + off);
    return __builtin_shufflevector(lo, hi, 0, 1, 2, 3, 4, 5, 6, 7);
  }
};
#endif

// Candidate hits of the triangles tested at once: lanes with a hit at t > tmin, and the
// values the hit needs.
template <int L>
struct HitsOf {
  using F = typename Simd<L>::F;
  unsigned mask;
  F t, v, w, det;
};
using BlockHits = HitsOf<4>;

// The sheared, permuted vertices relative to the ray's origin: the first step of the
// watertight test.
template <int L>
struct Sheared {
  using F = typename Simd<L>::F;
  F akx, aky, akz, bkx, bky, bkz, ckx, cky, ckz;
  F ax, ay, bx, by, cx, cy;
};

template <class Rows>
inline void shear(const TriRay& r, const Rows& rows, Sheared<Rows::lanes>& s) {
  using S = Simd<Rows::lanes>;
  using F = typename S::F;
  const int kx = r.kx * 4, ky = r.ky * 4, kz = r.kz * 4;
  const F okx = S::splat(r.org[r.kx]), oky = S::splat(r.org[r.ky]), okz = S::splat(r.org[r.kz]);
  const F sx = S::splat(r.sx), sy = S::splat(r.sy);
  s.akx = rows.row(0, kx) - okx, s.aky = rows.row(0, ky) - oky, s.akz = rows.row(0, kz) - okz;
  s.bkx = rows.row(1, kx) - okx, s.bky = rows.row(1, ky) - oky, s.bkz = rows.row(1, kz) - okz;
  s.ckx = rows.row(2, kx) - okx, s.cky = rows.row(2, ky) - oky, s.ckz = rows.row(2, kz) - okz;
  s.ax = s.akx - sx * s.akz, s.ay = s.aky - sy * s.akz;
  s.bx = s.bkx - sx * s.bkz, s.by = s.bky - sy * s.bkz;
  s.cx = s.ckx - sx * s.ckz, s.cy = s.cky - sy * s.ckz;
}

// The rare lanes (an edge function exactly 0, or NaN from overflowing products): the shear
// recomputed (same operations, same values) and the zero edge functions redone in double.
// Out of line, so the common path keeps nothing of the shear alive for it. Returns the lanes
// inside (all ones).
template <class Rows, class F = typename Simd<Rows::lanes>::F,
          class I = typename Simd<Rows::lanes>::I>
[[gnu::noinline]] I edges_slow(const TriRay& r, Rows rows, F& u, F& v, F& w, F& det) {
  using S = Simd<Rows::lanes>;
  Sheared<Rows::lanes> s;
  shear(r, rows, s);
  const F zero = {};
  unsigned retry = S::mask((u == zero) | (v == zero) | (w == zero));
  while (retry) {
    const unsigned i = ctz(retry);
    retry &= retry - 1;
    u[i] = float(double(s.cx[i]) * s.by[i] - double(s.cy[i]) * s.bx[i]);
    v[i] = float(double(s.ax[i]) * s.cy[i] - double(s.ay[i]) * s.cx[i]);
    w[i] = float(double(s.bx[i]) * s.ay[i] - double(s.by[i]) * s.ax[i]);
  }
  const I neg = (u < zero) | (v < zero) | (w < zero);
  const I pos = (u > zero) | (v > zero) | (w > zero);
  det = u + v + w;
  return ~(neg & pos);
}

// The watertight test (watertight_hit) on the rows' triangles at once: every lane performs
// the scalar test's operations in its order, so 4 and 8 lanes give the same values.
template <bool Reread, class Rows>
inline HitsOf<Rows::lanes> intersect_rows(const TriRay& r, Rows rows) {
  using S = Simd<Rows::lanes>;
  using F = typename S::F;
  using I = typename S::I;
  HitsOf<Rows::lanes> out;
  Sheared<Rows::lanes> s;
  shear(r, rows, s);
  F u = s.cx * s.by - s.cy * s.bx;
  F v = s.ax * s.cy - s.ay * s.cx;
  F w = s.bx * s.ay - s.by * s.ax;
  const F zero = {};
  F det = u + v + w;
  // Exact zeros (the double retry) and NaN (from overflowing products) take the slow path.
  const unsigned slow = S::mask((u == zero) | (v == zero) | (w == zero) | (det != det));
  I ok;
  if (__builtin_expect(slow == 0, 1)) {
    // No edge function is zero: the ray is inside when all three signs agree.
    const I ui = reinterpret_cast<I>(u), vi = reinterpret_cast<I>(v), wi = reinterpret_cast<I>(w);
    ok = ((ui ^ vi) | (ui ^ wi)) >= I{};
  } else {
    ok = edges_slow(r, rows, u, v, w, det);
  }
  ok &= det != zero;
  out.mask = S::mask(ok);
  if (!out.mask) return out;
  // Distance from the plane equation in the permuted axes (as watertight_hit).
  if constexpr (Reread) {
    // The vertices read again (same values): keeping the first reads alive through the edge
    // tests costs registers the traversal needs (any hit: 7-9 % faster on Sponza's diffuse rays;
    // closest hit: 3 % slower).
    asm("" : "+r"(rows.blk));
    shear(r, rows, s);
  }
  const F e10 = s.bkx - s.akx, e11 = s.bky - s.aky, e12 = s.bkz - s.akz;
  const F e20 = s.ckx - s.akx, e21 = s.cky - s.aky, e22 = s.ckz - s.akz;
  const F n0 = e11 * e22 - e12 * e21;
  const F n1 = e12 * e20 - e10 * e22;
  const F n2 = e10 * e21 - e11 * e20;
  const F ndd =
      n0 * S::splat(r.dir[r.kx]) + n1 * S::splat(r.dir[r.ky]) + n2 * S::splat(r.dir[r.kz]);
  const F t = (n0 * s.akx + n1 * s.aky + n2 * s.akz) / ndd;
  ok &= (ndd != zero) & (t > S::splat(r.tmin));
  out.mask = S::mask(ok);
  out.t = t;
  out.v = v;
  out.w = w;
  out.det = det;
  return out;
}

// One block's four triangles.
template <bool Reread = false>
inline BlockHits intersect_block(const TriRay& r, const TriangleBlock& blk) {
  return intersect_rows<Reread>(r, Rows4{&blk});
}

// Per-ray constants of the box test (SlabRay), splatted to W lanes.
inline float far_scale(float inv) {
  return inv * 1.00000072f;
}
template <int W>
struct BoxRay {
  using F = typename Simd<W>::F;
  F org[3], inv[3], inv_far[3];
  mutable typename Simd<W>::I test_mask;  // lanes hit by the last test (all ones / zeros)
  int near_row[3], far_row[3];            // rows of Bvh*Node::bounds holding the near / far planes
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
