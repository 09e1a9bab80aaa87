// The denoiser's kernels built for avx512 (flags in CMakeLists.txt).
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
namespace avx512_ns {
constexpr Isa kThisIsa = Isa::avx512;
#include "denoise/kernels.inl"
#include "denoise/svgf_kernels.inl"
}  // namespace avx512_ns

const KernelTable& kernels_avx512() {
  static const KernelTable table{avx512_ns::network, "avx512"};
  return table;
}

const SvgfKernels& svgf_kernels_avx512() {
  static const SvgfKernels table{avx512_ns::svgf_demodulate_rows, avx512_ns::svgf_temporal_rows,
                                 avx512_ns::svgf_pass_rows, avx512_ns::svgf_variance_rows};
  return table;
}

}  // namespace kestrel::denoise
