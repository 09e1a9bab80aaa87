// The upsampler's per-pixel stages built for avx512 (-mavx512f; flags in CMakeLists.txt).
#include <immintrin.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <vector>

#include "upscale/reconstruct.h"

namespace kestrel::upscale {
namespace avx512_ns {
constexpr float kLuma[3] = {0.2126f, 0.7152f, 0.0722f};
// clang-format off
#include "core/simd/lanes.inl"
#include "upscale/sampling.inl"  // clampi
#include "upscale/prepare.inl"
#include "upscale/reconstruct.inl"
#include "upscale/nsrr_blend.inl"
// clang-format on
}  // namespace avx512_ns

const UpscaleKernels& upscale_kernels_avx512() {
  static const UpscaleKernels table{avx512_ns::input_rows,        avx512_ns::stats_rows,
                                    avx512_ns::disocclusion_rows, avx512_ns::features_rows,
                                    avx512_ns::reconstruct_rows,  avx512_ns::zero_upsample_rows,
                                    avx512_ns::blend_row};
  return table;
}

}  // namespace kestrel::upscale
