// The geometry of hits several at a time in SIMD lanes: what surface_geometry and surface_at
// compute before the material (position, geometric normal facing the ray, the cosine there,
// shading normal, texture coordinates), for the lanes of a group whose hits lie on one triangle
// mesh with an identity transform, written as structure-of-arrays rows. Compiled once per
// instruction set (surface_rows_<isa>.cpp include surface_rows.inl with -ffp-contract=off) and
// picked by default_isa(); every lane does the scalar code's operations in its order, so the
// values are the same bits.
#pragma once
#include <cstddef>
#include <cstdint>

#include "kestrel/instances.h"
#include "kestrel/isa.h"
#include "kestrel/types.h"

namespace kestrel::render {

/// Rows of hits: entry j is the j-th hit of the group.
struct SurfaceRows {
  static constexpr int size = 16;      // hits per group (the widest lanes)
  float px[size], py[size], pz[size];  // position
  float gx[size], gy[size], gz[size];  // unit geometric normal facing the ray (wo without area)
  float cos_hit[size];                 // its cosine with wo before it was turned to face it
  float nx[size], ny[size], nz[size];  // shading normal (the geometric one where normals fail)
  float u[size], v[size];              // texture coordinates (0 without)
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
  SurfaceRows* out = nullptr;
};

using SurfaceRowsKernel = void (*)(const SurfaceRowsArgs& a);
SurfaceRowsKernel surface_rows_sse2();
SurfaceRowsKernel surface_rows_avx2();
SurfaceRowsKernel surface_rows_avx512();
/// The kernel of an ISA (Error when this CPU lacks it).
SurfaceRowsKernel surface_rows_kernel(Isa isa);

}  // namespace kestrel::render
