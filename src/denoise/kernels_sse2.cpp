// The denoiser's kernels built for sse2 (flags in CMakeLists.txt).
#include "core/parallel.h"
#include <xmmintrin.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstring>
#include <vector>

#include "denoise/kernels.h"

namespace kestrel::denoise {
namespace sse2_ns {
#include "denoise/kernels.inl"
}  // namespace sse2_ns

const KernelTable& kernels_sse2() {
  static const KernelTable table{sse2_ns::network, sse2_ns::conv_layer, "sse2"};
  return table;
}

}  // namespace kestrel::denoise
