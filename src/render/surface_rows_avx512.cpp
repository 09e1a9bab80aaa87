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

const SurfaceRowsKernels& surface_rows_avx512() {
  static const SurfaceRowsKernels table{avx512_ns::surface_rows, avx512_ns::texel_rows,
                                        avx512_ns::camera_rows, avx512_ns::path_draws};
  return table;
}

}  // namespace kestrel::render
