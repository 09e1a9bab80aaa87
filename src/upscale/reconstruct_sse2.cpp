// The upsampler's per-pixel stages built for sse2 (the x86-64 baseline; flags in CMakeLists.txt).
#include <immintrin.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <vector>

#include "upscale/reconstruct.h"

namespace kestrel::upscale {
namespace sse2_ns {
constexpr float kLuma[3] = {0.2126f, 0.7152f, 0.0722f};
// clang-format off
#include "core/simd/lanes.inl"
#include "upscale/sampling.inl"  // clampi
#include "upscale/prepare.inl"
#include "upscale/reconstruct.inl"
#include "upscale/nsrr_blend.inl"
// clang-format on
}  // namespace sse2_ns

const UpscaleKernels& upscale_kernels_sse2() {
  static const UpscaleKernels table{sse2_ns::input_rows,        sse2_ns::stats_rows,
                                    sse2_ns::disocclusion_rows, sse2_ns::features_rows,
                                    sse2_ns::reconstruct_rows,  sse2_ns::zero_upsample_rows,
                                    sse2_ns::blend_row};
  return table;
}

}  // namespace kestrel::upscale
