// The denoiser's kernels built for avx2 (flags in CMakeLists.txt).
#include <immintrin.h>
#include "core/parallel.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstring>
#include <vector>

#include "denoise/kernels.h"
#include "denoise/svgf.h"
#include "nn/conv.h"

namespace kestrel::denoise {
namespace avx2_ns {
constexpr Isa kThisIsa = Isa::avx2;
#include "denoise/kernels.inl"
#include "denoise/svgf_kernels.inl"
}  // namespace avx2_ns

const KernelTable& kernels_avx2() {
  static const KernelTable table{avx2_ns::network, "avx2"};
  return table;
}

const SvgfKernels& svgf_kernels_avx2() {
  static const SvgfKernels table{avx2_ns::svgf_demodulate_rows, avx2_ns::svgf_temporal_rows,
                                 avx2_ns::svgf_pass_rows, avx2_ns::svgf_variance_rows};
  return table;
}

}  // namespace kestrel::denoise
