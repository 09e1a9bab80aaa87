// Which instruction set's convolution kernels run.
#include "nn/conv.h"

namespace kestrel::nn {

const ConvKernels& conv_kernels(Isa isa) {
  require_supported(isa);
  switch (isa) {
    case Isa::avx512:
      return conv_kernels_avx512();
    case Isa::avx2:
      return conv_kernels_avx2();
    default:
      return conv_kernels_sse2();
  }
}

}  // namespace kestrel::nn
