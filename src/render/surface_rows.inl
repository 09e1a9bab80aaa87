// surface_rows' kernel for one instruction set: included by surface_rows_<isa>.cpp inside a
// namespace of their own, after core/simd/lanes.inl. The body is written once over T = float
// (a group's tail) and T = vfloat (kLanes hits at a time); each lane does the operations of
// surface_geometry, surface_at and uv_at in their order. Lanes whose hit is on another
// instance (or none) read triangle 0 and their entries are left for the caller to ignore.

static inline int bits_of(float x) {
  return __builtin_bit_cast(int, x);
}
static inline vint bits_of(vfloat x) {
  return (vint)x;
}

// Attribute c (n floats per vertex) of the vertices i0, i1, i2 interpolated with the
// barycentric weights b0, b1, b2 as Vec3's / Vec2's operators do: (a b0 + b b1) + c b2.
template <class T, class I>
static inline T interpolate(const float* base, I i0, I i1, I i2, int n, int c, T b0, T b1, T b2) {
  return vgather(base, i0 * n + c) * b0 + vgather(base, i1 * n + c) * b1 +
         vgather(base, i2 * n + c) * b2;
}

template <class T>
static inline void surface_lanes(const SurfaceRowsArgs& a, int j) {
  using I = lanes_int<T>;
  SurfaceRows& o = *a.out;
  const I kv = lane_iota(I{}) + j;
  // InstanceHit: t, prim_id, instance_id, u, v; Ray: org, dir, tmin, tmax.
  const float* hf = reinterpret_cast<const float*>(a.hits);
  const float* rf = reinterpret_cast<const float*>(a.rays);
  const I h5 = kv * 5, r8 = kv * 8;
  const I mine = bits_of(vgather(hf, h5 + 2)) == int(a.instance);
  const I tri = mine ? bits_of(vgather(hf, h5 + 1)) * 3 : I{};
  const T u = vgather(hf, h5 + 3), v = vgather(hf, h5 + 4);
  const T wx = -vgather(rf, r8 + 3), wy = -vgather(rf, r8 + 4), wz = -vgather(rf, r8 + 5);
  const float* ixf = reinterpret_cast<const float*>(a.indices);
  const I i0 = bits_of(vgather(ixf, tri)), i1 = bits_of(vgather(ixf, tri + 1)),
          i2 = bits_of(vgather(ixf, tri + 2));
  const T b0 = (1.0f - u) - v;
  // Position and geometric normal (surface_geometry).
  const float* pf = reinterpret_cast<const float*>(a.positions);
  T p0x = vgather(pf, i0 * 3), p0y = vgather(pf, i0 * 3 + 1), p0z = vgather(pf, i0 * 3 + 2);
  T p1x = vgather(pf, i1 * 3), p1y = vgather(pf, i1 * 3 + 1), p1z = vgather(pf, i1 * 3 + 2);
  T p2x = vgather(pf, i2 * 3), p2y = vgather(pf, i2 * 3 + 1), p2z = vgather(pf, i2 * 3 + 2);
  st(o.ox + j, p0x * b0 + p1x * u + p2x * v);
  st(o.oy + j, p0y * b0 + p1y * u + p2y * v);
  st(o.oz + j, p0z * b0 + p1z * u + p2z * v);
  if (const float* m = a.xf) {  // the vertices in world space (Affine3::point)
    const auto point = [m](T& x, T& y, T& z) {
      const T wx_ = m[0] * x + m[1] * y + m[2] * z + m[3],
              wy_ = m[4] * x + m[5] * y + m[6] * z + m[7],
              wz_ = m[8] * x + m[9] * y + m[10] * z + m[11];
      x = wx_, y = wy_, z = wz_;
    };
    point(p0x, p0y, p0z), point(p1x, p1y, p1z), point(p2x, p2y, p2z);
  }
  st(o.px + j, p0x * b0 + p1x * u + p2x * v);
  st(o.py + j, p0y * b0 + p1y * u + p2y * v);
  st(o.pz + j, p0z * b0 + p1z * u + p2z * v);
  const T e1x = p1x - p0x, e1y = p1y - p0y, e1z = p1z - p0z;
  const T e2x = p2x - p0x, e2y = p2y - p0y, e2z = p2z - p0z;
  T gx = e1y * e2z - e1z * e2y, gy = e1z * e2x - e1x * e2z, gz = e1x * e2y - e1y * e2x;
  const T glen = vsqrt(gx * gx + gy * gy + gz * gz);
  const auto area = glen > 0.0f;
  const T ginv = 1.0f / glen;
  gx = area ? gx * ginv : -wx, gy = area ? gy * ginv : -wy, gz = area ? gz * ginv : -wz;
  const T cos_hit = gx * wx + gy * wy + gz * wz;
  const auto back = cos_hit < 0.0f;
  gx = back ? -gx : gx, gy = back ? -gy : gy, gz = back ? -gz : gz;
  st(o.gx + j, gx), st(o.gy + j, gy), st(o.gz + j, gz), st(o.cos_hit + j, cos_hit);
  // Shading normal (surface_at): the interpolated vertex normal where it has a finite,
  // non-zero length, turned to the geometric normal's side, and seen from wo.
  T nx = gx, ny = gy, nz = gz;
  if (a.normals) {
    const float* nf = reinterpret_cast<const float*>(a.normals);
    T mx = interpolate(nf, i0, i1, i2, 3, 0, b0, u, v),
      my = interpolate(nf, i0, i1, i2, 3, 1, b0, u, v),
      mz = interpolate(nf, i0, i1, i2, 3, 2, b0, u, v);
    if (const float* q = a.nrm) {  // normal_transform
      const T tx = q[0] * mx + q[1] * my + q[2] * mz, ty = q[3] * mx + q[4] * my + q[5] * mz,
              tz = q[6] * mx + q[7] * my + q[8] * mz;
      mx = tx, my = ty, mz = tz;
    }
    const T len = vsqrt(mx * mx + my * my + mz * mz);
    const auto ok = (len > 0.0f) & (len < INFINITY);
    const T inv = 1.0f / len;
    mx = mx * inv, my = my * inv, mz = mz * inv;
    const auto flip = (mx * gx + my * gy + mz * gz) < 0.0f;
    mx = flip ? -mx : mx, my = flip ? -my : my, mz = flip ? -mz : mz;
    const auto use = ok & ((mx * wx + my * wy + mz * wz) > 1e-4f);
    nx = use ? mx : nx, ny = use ? my : ny, nz = use ? mz : nz;
  }
  st(o.nx + j, nx), st(o.ny + j, ny), st(o.nz + j, nz);
  // Texture coordinates (uv_at).
  if (a.uvs) {
    const float* tf = reinterpret_cast<const float*>(a.uvs);
    st(o.u + j, interpolate(tf, i0, i1, i2, 2, 0, b0, u, v));
    st(o.v + j, interpolate(tf, i0, i1, i2, 2, 1, b0, u, v));
  } else {
    st(o.u + j, T{}), st(o.v + j, T{});
  }
}

static void surface_rows(const SurfaceRowsArgs& a) {
  int j = 0;
  const int n = int(a.n);
  for (; j + kLanes <= n; j += kLanes) surface_lanes<vfloat>(a, j);
  for (; j < n; ++j) surface_lanes<float>(a, j);
}

// floor_exact (render/fast_math.h) lane by lane: the truncation, one lower where it rounded up,
// the sign of x kept (-0 stays -0); floats of at least 2^23, NaN and the infinities unchanged.
static inline float floor_lanes(float x) {
  if (!(std::fabs(x) < 0x1p23f)) return x;
  float t = float(int(x));
  if (t > x) t -= 1.0f;
  return std::copysign(t, x);
}
static inline vfloat floor_lanes(vfloat x) {
  const vint small = vabs(x) < 0x1p23f;
  vfloat t = __builtin_convertvector(__builtin_convertvector(small ? x : vfloat{}, vint), vfloat);
  t = t > x ? t - 1.0f : t;
  t = (vfloat)(((vint)t & 0x7FFFFFFF) | ((vint)x & int(0x80000000u)));
  return small ? t : x;
}

// sample_texture's bilinear, repeat-wrapped, sRGB-decoded fetch for entries j .. j + lanes.
template <class T>
static inline void texel_lanes(const TexelRowsArgs& a, int j) {
  using I = lanes_int<T>;
  SurfaceRows& o = *a.rows;
  const float w = float(a.width), h = float(a.height);
  const T u = ld<T>(o.u + j), v = ld<T>(o.v + j);
  T x = (u - floor_lanes(u)) * w - 0.5f, y = (v - floor_lanes(v)) * h - 0.5f;
  const auto inside = (x >= -1.0f) & (x < w) & (y >= -1.0f) & (y < h);  // false for NaN
  x = inside ? x : T{}, y = inside ? y : T{};
  const T fx = floor_lanes(x), fy = floor_lanes(y);
  const T wx = x - fx, wy = y - fy;
  I x0 = vtrunc(fx), y0 = vtrunc(fy);
  I x1 = x0 + 1, y1 = y0 + 1;
  x0 = x0 < 0 ? I{} + (a.width - 1) : x0, x1 = x1 >= a.width ? I{} : x1;
  y0 = y0 < 0 ? I{} + (a.height - 1) : y0, y1 = y1 >= a.height ? I{} : y1;
  const float* texels = reinterpret_cast<const float*>(a.rgba);
  const I row0 = y0 * a.width, row1 = y1 * a.width;
  const I t00 = bits_of(vgather(texels, row0 + x0)), t10 = bits_of(vgather(texels, row0 + x1)),
          t01 = bits_of(vgather(texels, row1 + x0)), t11 = bits_of(vgather(texels, row1 + x1));
  const T w00 = (1.0f - wx) * (1.0f - wy), w10 = wx * (1.0f - wy), w01 = (1.0f - wx) * wy,
          w11 = wx * wy;
  float* out[3] = {o.tr, o.tg, o.tb};
  for (int c = 0; c < 3; ++c) {
    const int shift = 8 * c;
    st(out[c] + j, vgather(a.srgb, (t00 >> shift) & 255) * w00 +
                       vgather(a.srgb, (t10 >> shift) & 255) * w10 +
                       vgather(a.srgb, (t01 >> shift) & 255) * w01 +
                       vgather(a.srgb, (t11 >> shift) & 255) * w11);
  }
}

static void texel_rows(const TexelRowsArgs& a) {
  int j = 0;
  const int n = int(a.n);
  for (; j + kLanes <= n; j += kLanes) texel_lanes<vfloat>(a, j);
  for (; j < n; ++j) texel_lanes<float>(a, j);
}

// ---- camera rows ---------------------------------------------------------------------------
// Rng's seeding (pcg_seed) and three steps (render/sampling.h) and CameraModel::ray without a lens
// (renderer_impl.h) lane by lane: the same integer operations, the float ones in their order.
typedef uint64_t vu64 __attribute__((vector_size(8 * kLanes)));
template <class T>  // 64-bit lanes as many as T's: uint64_t for float, vu64 for vfloat
using lanes_u64 = std::conditional_t<std::is_same_v<T, float>, uint64_t, vu64>;
static inline uint64_t u64_of(int v) {
  return uint64_t(v);
}
static inline vu64 u64_of(vint v) {
  return __builtin_convertvector(v, vu64);
}
static inline void st64(uint64_t* p, uint64_t v) {
  *p = v;
}
static inline void st64(uint64_t* p, vu64 v) {
  std::memcpy(p, &v, sizeof v);
}

template <class T>
static inline void camera_lanes(const CameraRowsArgs& a, int j) {
  using I = lanes_int<T>;
  const I x = ldi<I>(a.x + j), y = ldi<I>(a.y + j);
  using U = lanes_u64<T>;
  const U pixel = u64_of(y) * uint64_t(a.image_width) + u64_of(x);
  U state, inc;
  pcg_seed(a.seed, a.frame, pixel, a.sample, state, inc);
  for (int k = 0; k < 3; ++k) state = state * pcg_multiplier + inc;  // next()
  st64(a.state + j, state);
  st64(a.inc + j, inc);
  const T fx = vfloat_of(x) + a.jx, fy = vfloat_of(y) + a.jy;
  const T sx = (2.0f * fx / float(a.width) - 1.0f) * a.tan_half * a.aspect;
  const T sy = (1.0f - 2.0f * fy / float(a.height)) * a.tan_half;
  const Vec3 &f = a.basis[0], &r = a.basis[1], &u = a.basis[2];
  const T dx = (f.x + r.x * sx) + u.x * sy, dy = (f.y + r.y * sx) + u.y * sy,
          dz = (f.z + r.z * sx) + u.z * sy;
  const T inv = 1.0f / vsqrt(dx * dx + dy * dy + dz * dz);
  st(a.dx + j, dx * inv), st(a.dy + j, dy * inv), st(a.dz + j, dz * inv);
}

static void camera_rows(const CameraRowsArgs& a) {
  int j = 0;
  const int n = int(a.n);
  for (; j + kLanes <= n; j += kLanes) camera_lanes<vfloat>(a, j);
  for (; j < n; ++j) camera_lanes<float>(a, j);
}

// ---- path draws ----------------------------------------------------------------------------
// Rng::uniform six times, Renderer::Impl::sun_sample (with sincos_2pi and Basis::to_world) and
// BsdfAt::sample's cosine direction lane by lane: the same integer operations, the float ones
// in their order.
typedef uint32_t vu32 __attribute__((vector_size(4 * kLanes)));
static inline uint32_t u32_of(uint64_t v) {
  return uint32_t(v);
}
static inline vu32 u32_of(vu64 v) {
  return __builtin_convertvector(v, vu32);
}
static inline float float_of24(uint32_t v) {  // v < 2^24: exact
  return float(v);
}
static inline vfloat float_of24(vu32 v) {
  return __builtin_convertvector((vint)v, vfloat);
}
template <class U>
static inline U ld64(const uint64_t* p) {
  U v;
  std::memcpy(&v, p, sizeof v);
  return v;
}

template <class T, class U>
static inline T uniform_lanes(U& state, U inc) {  // Rng::next, Rng::uniform
  const U old = state;
  state = old * pcg_multiplier + inc;
  const auto xorshifted = u32_of(((old >> 18u) ^ old) >> 27u);
  const auto rot = u32_of(old >> 59u);
  const auto r = (xorshifted >> rot) | (xorshifted << ((32u - rot) & 31u));
  return float_of24(r >> 8) * 0x1p-24f;
}

template <class T>
static inline T round_even_lanes(T x) {  // round_even
  const T a = vabs(x);
  const T r = (a + 0x1p23f) - 0x1p23f;
  const auto small = a < 0x1p23f;  // false for NaN
  const auto sign = bits_of(x) & int(0x80000000u);
  const T signed_r = __builtin_bit_cast(T, bits_of(r) | sign);
  return small ? signed_r : x;
}

// sincos_2pi lane by lane.
template <class T>
static inline void sincos_2pi_lanes(T u, T& s, T& c) {
  const T r = u - round_even_lanes(u);
  const T q = round_even_lanes(4.0f * r);
  const T t = (r - 0.25f * q) * 6.28318531f;
  T sn, cs;
  sincos_taylor(t, sn, cs);
  sincos_quadrant(vtrunc(q) & 3, sn, cs, s, c);
}

template <class T>
static inline void path_draw_lanes(const PathDrawsArgs& a, int j) {
  using U = lanes_u64<T>;
  U state = ld64<U>(a.state + j);
  const U inc = ld64<U>(a.inc + j);
  PathDraws& o = *a.out;
  const T ul = uniform_lanes<T>(state, inc);
  const T u1 = uniform_lanes<T>(state, inc);
  const T u2 = uniform_lanes<T>(state, inc);
  st(o.ul + j, ul), st(o.u1 + j, u1), st(o.u2 + j, u2);
  st64(o.state3 + j, state);
  const T b0 = uniform_lanes<T>(state, inc);
  const T b1 = uniform_lanes<T>(state, inc);
  const T b2 = uniform_lanes<T>(state, inc);
  st(o.b0 + j, b0), st(o.b1 + j, b1), st(o.b2 + j, b2);
  st64(o.state6 + j, state);
  // The cosine lobe's direction (BsdfAt::sample).
  T sin_phi, cos_phi;
  const T r = vsqrt(b1);
  sincos_2pi_lanes(b2, sin_phi, cos_phi);
  const T zz = 1.0f - b1;
  st(o.cx + j, r * cos_phi), st(o.cy + j, r * sin_phi), st(o.cz + j, vsqrt(0.0f < zz ? zz : T{}));
  if (!a.sun_frame) return;
  // sun_sample, then Basis::to_world.
  const T cos_t = 1.0f - u1 * (1.0f - a.sun_cos_max);
  const T q2 = 1.0f - cos_t * cos_t;
  const T sin_t = vsqrt(0.0f < q2 ? q2 : T{});
  sincos_2pi_lanes(u2, sin_phi, cos_phi);
  const T vx = sin_t * cos_phi, vy = sin_t * sin_phi, vz = cos_t;
  const Vec3 &bt = a.sun_frame[0], &bb = a.sun_frame[1], &bn = a.sun_frame[2];
  st(o.sx + j, (bt.x * vx + bb.x * vy) + bn.x * vz);
  st(o.sy + j, (bt.y * vx + bb.y * vy) + bn.y * vz);
  st(o.sz + j, (bt.z * vx + bb.z * vy) + bn.z * vz);
}

static void path_draws(const PathDrawsArgs& a) {
  int j = 0;
  const int n = int(a.n);
  for (; j + kLanes <= n; j += kLanes) path_draw_lanes<vfloat>(a, j);
  for (; j < n; ++j) path_draw_lanes<float>(a, j);
}
