// surface_rows' kernel built for avx2 (flags in CMakeLists.txt).
#include <immintrin.h>

#include <cmath>
#include <cstring>

#include "render/surface_rows.h"

namespace kestrel::render {
namespace avx2_ns {
// clang-format off
#include "core/simd/lanes.inl"
#include "render/surface_rows.inl"
// clang-format on
}  // namespace avx2_ns

SurfaceRowsKernel surface_rows_avx2() {
  return avx2_ns::surface_rows;
}

}  // namespace kestrel::render
