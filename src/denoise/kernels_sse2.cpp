// The denoiser's kernels built for sse2 (flags in CMakeLists.txt).
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
namespace sse2_ns {
constexpr Isa kThisIsa = Isa::sse2;
#include "denoise/kernels.inl"
#include "denoise/svgf_kernels.inl"
}  // namespace sse2_ns

const KernelTable& kernels_sse2() {
  static const KernelTable table{sse2_ns::network, "sse2"};
  return table;
}

const SvgfKernels& svgf_kernels_sse2() {
  static const SvgfKernels table{sse2_ns::svgf_demodulate_rows, sse2_ns::svgf_temporal_rows,
                                 sse2_ns::svgf_pass_rows, sse2_ns::svgf_variance_rows};
  return table;
}

}  // namespace kestrel::denoise
