// surface_rows' kernel built for sse2 (flags in CMakeLists.txt).
#include <immintrin.h>

#include <cmath>
#include <cstring>

#include "render/surface_rows.h"

namespace kestrel::render {
namespace sse2_ns {
// clang-format off
#include "core/simd/lanes.inl"
#include "render/surface_rows.inl"
// clang-format on
}  // namespace sse2_ns

SurfaceRowsKernel surface_rows_sse2() {
  return sse2_ns::surface_rows;
}

}  // namespace kestrel::render
