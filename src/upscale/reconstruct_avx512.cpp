// The upsampler's reconstruction built for avx512 (-mavx512f, as the earlier target_clones
// "avx512f" clone; flags in CMakeLists.txt).
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
#include "core/simd.inl"
#include "upscale/sampling.inl"  // clampi
#include "upscale/reconstruct.inl"
// clang-format on
}  // namespace avx512_ns

ReconstructFn reconstruct_avx512() {
  return avx512_ns::reconstruct_rows;
}

}  // namespace kestrel::upscale
