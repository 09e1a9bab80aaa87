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

const SurfaceRowsKernels& surface_rows_avx2() {
  static const SurfaceRowsKernels table{avx2_ns::surface_rows, avx2_ns::texel_rows,
                                        avx2_ns::camera_rows, avx2_ns::path_draws};
  return table;
}

}  // namespace kestrel::render
