// The convolution kernels built for sse2 (flags in CMakeLists.txt).
#include <xmmintrin.h>

#include <algorithm>
#include <cstring>
#include <vector>

#include "core/parallel.h"
#include "nn/conv.h"

namespace kestrel::nn {
namespace sse2_ns {
#include "nn/conv.inl"
}  // namespace sse2_ns

const ConvKernels& conv_kernels_sse2() {
  static const ConvKernels table{sse2_ns::conv_layer, "sse2"};
  return table;
}

}  // namespace kestrel::nn
