// The bf16 convolution kernel, built for AVX-512 with BF16 (flags in CMakeLists.txt): chosen
// by conv_kernels(Isa::avx512, true) where the CPU has AVX512_BF16.
#include <immintrin.h>

#include <algorithm>
#include <cstring>
#include <vector>

#include "core/parallel.h"
#include "nn/conv.h"

namespace kestrel::nn {
namespace avx512bf16_ns {
#include "nn/conv.inl"
}  // namespace avx512bf16_ns

const ConvKernels& conv_kernels_avx512_bf16() {
  static const ConvKernels table{avx512bf16_ns::conv_layer_bf16, "avx512-bf16", true};
  return table;
}

}  // namespace kestrel::nn
