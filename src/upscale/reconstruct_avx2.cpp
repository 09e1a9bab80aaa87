// The upsampler's per-pixel stages built for avx2 (-march=haswell; flags in CMakeLists.txt).
#include <immintrin.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <vector>

#include "upscale/reconstruct.h"

namespace kestrel::upscale {
namespace avx2_ns {
constexpr float kLuma[3] = {0.2126f, 0.7152f, 0.0722f};
// clang-format off
#include "core/simd/lanes.inl"
#include "upscale/sampling.inl"  // clampi
#include "upscale/prepare.inl"
#include "upscale/reconstruct.inl"
#include "upscale/nsrr_blend.inl"
// clang-format on
}  // namespace avx2_ns

const UpscaleKernels& upscale_kernels_avx2() {
  static const UpscaleKernels table{avx2_ns::input_rows,        avx2_ns::stats_rows,
                                    avx2_ns::disocclusion_rows, avx2_ns::features_rows,
                                    avx2_ns::reconstruct_rows,  avx2_ns::zero_upsample_rows,
                                    avx2_ns::blend_row};
  return table;
}

}  // namespace kestrel::upscale
