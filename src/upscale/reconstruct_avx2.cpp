// The upsampler's reconstruction built for avx2 (-march=haswell, as the earlier target_clones
// "arch=haswell" clone; flags in CMakeLists.txt).
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
#include "core/simd.inl"
#include "upscale/sampling.inl"  // clampi
#include "upscale/reconstruct.inl"
// clang-format on
}  // namespace avx2_ns

ReconstructFn reconstruct_avx2() {
  return avx2_ns::reconstruct_rows;
}

}  // namespace kestrel::upscale
