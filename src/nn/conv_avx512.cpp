// The convolution kernels built for avx512 (flags in CMakeLists.txt).
#include <xmmintrin.h>

#include <algorithm>
#include <cstring>
#include <vector>

#include "core/parallel.h"
#include "nn/conv.h"

namespace kestrel::nn {
namespace avx512_ns {
#include "nn/conv.inl"
}  // namespace avx512_ns

const ConvKernels& conv_kernels_avx512() {
  static const ConvKernels table{avx512_ns::conv_layer, "avx512"};
  return table;
}

}  // namespace kestrel::nn
