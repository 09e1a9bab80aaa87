// The upsampler's reconstruction built for sse2 (the x86-64 baseline; flags in CMakeLists.txt).
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
#include "core/simd.inl"
#include "upscale/sampling.inl"  // clampi
#include "upscale/reconstruct.inl"
// clang-format on
}  // namespace sse2_ns

ReconstructFn reconstruct_sse2() {
  return sse2_ns::reconstruct_rows;
}

}  // namespace kestrel::upscale
