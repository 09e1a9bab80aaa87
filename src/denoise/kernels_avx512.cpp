// The denoiser's kernels built for avx512 (flags in CMakeLists.txt).
#include <xmmintrin.h>
#include "core/parallel.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstring>
#include <vector>

#include "denoise/kernels.h"
#include "nn/conv.h"

namespace kestrel::denoise {
namespace avx512_ns {
constexpr Isa kThisIsa = Isa::avx512;
#include "denoise/kernels.inl"
}  // namespace avx512_ns

const KernelTable& kernels_avx512() {
  static const KernelTable table{avx512_ns::network, "avx512"};
  return table;
}

}  // namespace kestrel::denoise
