// The convolution kernels built for avx2 (flags in CMakeLists.txt).
#include <xmmintrin.h>

#include <algorithm>
#include <cstring>
#include <vector>

#include "core/parallel.h"
#include "nn/conv.h"

namespace kestrel::nn {
namespace avx2_ns {
#include "nn/conv.inl"
}  // namespace avx2_ns

const ConvKernels& conv_kernels_avx2() {
  static const ConvKernels table{avx2_ns::conv_layer, "avx2"};
  return table;
}

}  // namespace kestrel::nn
