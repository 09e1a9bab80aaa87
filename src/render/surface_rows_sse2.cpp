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

const SurfaceRowsKernels& surface_rows_sse2() {
  static const SurfaceRowsKernels table{sse2_ns::surface_rows, sse2_ns::texel_rows,
                                        sse2_ns::camera_rows, sse2_ns::path_draws};
  return table;
}

}  // namespace kestrel::render
