// surface_rows' kernel built for avx512 (flags in CMakeLists.txt).
#include <immintrin.h>

#include <cmath>
#include <cstring>

#include "render/surface_rows.h"

namespace kestrel::render {
namespace avx512_ns {
// clang-format off
#include "core/simd/lanes.inl"
#include "render/surface_rows.inl"
// clang-format on
}  // namespace avx512_ns

SurfaceRowsKernel surface_rows_avx512() {
  return avx512_ns::surface_rows;
}

}  // namespace kestrel::render
