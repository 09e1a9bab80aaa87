// The surfaces of hits several at a time in SIMD lanes: what surface_geometry and surface_at
// compute before the material (position, geometric normal facing the ray, the cosine there,
// shading normal, texture coordinates) and the base colour's texel, for the lanes of a group whose
// hits lie on one instance, written as structure-of-arrays rows; and a tile's camera rays with
// their paths' random number generators.
// Compiled once per instruction set (surface_rows_<isa>.cpp include surface_rows.inl with
// -ffp-contract=off) and picked by default_isa(); every lane does the scalar code's operations in
// its order, so the values are the same bits.
#pragma once
#include <cstddef>
#include <cstdint>
#include <type_traits>

#include "kestrel/instances.h"
#include "kestrel/isa.h"
#include "kestrel/types.h"
#include "render/fast_math.h"
#include "render/sampling.h"

namespace kestrel::render {

/// Rows of hits: entry j is the j-th hit of the group.
struct SurfaceRows {
  static constexpr int size = 16;      // hits per group (the widest lanes)
  float px[size], py[size], pz[size];  // position
  float ox[size], oy[size], oz[size];  // position in the instance's object space
  float gx[size], gy[size], gz[size];  // unit geometric normal facing the ray (wo without area)
  float cos_hit[size];                 // its cosine with wo before it was turned to face it
  float nx[size], ny[size], nz[size];  // shading normal (the geometric one where normals fail)
  float u[size], v[size];              // texture coordinates (0 without)
  float tr[size], tg[size], tb[size];  // base-colour texel (sample_texture, sRGB decoded)
  uint32_t texel = 0;                  // bit j: tr, tg, tb hold hit j's base texel
};

struct SurfaceRowsArgs {
  const uint32_t* indices = nullptr;  // the mesh's, 3 per triangle
  const Vec3* positions = nullptr;
  const Vec3* normals = nullptr;      // or null
  const Vec2* uvs = nullptr;          // or null
  const InstanceHit* hits = nullptr;  // the group's (n of them)
  const Ray* rays = nullptr;          // their rays
  size_t n = 0;                       // 1 .. SurfaceRows::size
  uint32_t instance = 0;              // the lanes whose hit is on this instance are computed
  const float* xf = nullptr;   // its object-to-world transform (Affine3::m), null: the identity
  const float* nrm = nullptr;  // with xf: its normal transform (the inverse transpose, 3 x 3)
  SurfaceRows* out = nullptr;
};

/// One texture's bilinear, repeat-wrapped, sRGB-decoded texel (sample_texture's) at the rows'
/// texture coordinates, for the first n entries, into tr, tg, tb.
struct TexelRowsArgs {
  const uint8_t* rgba = nullptr;  // width * height texels of 4 bytes
  int width = 0, height = 0;      // width * height < 2^31
  const float* srgb = nullptr;    // srgb_decode_table()
  size_t n = 0;
  SurfaceRows* rows = nullptr;
};

/// A pinhole camera's rays (CameraModel::ray, aperture 0) at pixels (x, y) and their paths'
/// random number generators: Rng(seed, frame, pixel, sample) after the ctor's draw and the two
/// lens draws ray() is given, pixel = y * image_width + x; n of them.
struct CameraRowsArgs {
  uint64_t seed = 0, frame = 0, sample = 0;
  int image_width = 0;
  const int* x = nullptr;  // n pixel columns, then rows
  const int* y = nullptr;
  size_t n = 0;
  float jx = 0, jy = 0;         // the frame's jitter
  const Vec3* basis = nullptr;  // the camera's forward, right and up
  float tan_half = 0, aspect = 0;
  int width = 0, height = 0;  // the camera's (CameraModel::width, height)
  uint64_t* state = nullptr;  // out, n each: the generators' state and increment
  uint64_t* inc = nullptr;
  float* dx = nullptr;  // out, n each: the rays' unit directions
  float* dy = nullptr;
  float* dz = nullptr;
};

/// A group's next draws, made ahead of the shading loop from each path's generator (state and
/// increment) without advancing it: sample_light's three uniforms (ul, u1, u2) and the sun's
/// direction for them (sun_sample), then the BSDF sample's three (b0, b1, b2) and the cosine
/// lobe's direction for them (BsdfAt::sample), and the generator's state after three and
/// after six.
struct PathDraws {
  static constexpr int size = SurfaceRows::size;
  float ul[size], u1[size], u2[size];
  uint64_t state3[size];
  float sx[size], sy[size], sz[size];  // when made with a sun
  float b0[size], b1[size], b2[size];
  uint64_t state6[size];
  float cx[size], cy[size], cz[size];  // local frame: z = the shading normal
};
struct PathDrawsArgs {
  const uint64_t* state = nullptr;  // n each: the generators' state and increment
  const uint64_t* inc = nullptr;
  size_t n = 0;
  const Vec3* sun_frame = nullptr;  // the sun's cone's basis (t, b, n), or null: no sun
  float sun_cos_max = 1;
  PathDraws* out = nullptr;
};

using SurfaceRowsKernel = void (*)(const SurfaceRowsArgs& a);
using TexelRowsKernel = void (*)(const TexelRowsArgs& a);
using CameraRowsKernel = void (*)(const CameraRowsArgs& a);
using PathDrawsKernel = void (*)(const PathDrawsArgs& a);
struct SurfaceRowsKernels {
  SurfaceRowsKernel surfaces;
  TexelRowsKernel texels;
  CameraRowsKernel camera;
  PathDrawsKernel draws;
};
const SurfaceRowsKernels& surface_rows_sse2();
const SurfaceRowsKernels& surface_rows_avx2();
const SurfaceRowsKernels& surface_rows_avx512();
/// The kernels of an ISA (Error when this CPU lacks it).
const SurfaceRowsKernels& surface_rows_kernels(Isa isa);

}  // namespace kestrel::render
