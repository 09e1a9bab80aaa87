// Which instruction set's convolution kernels run.
#include "nn/conv.h"

namespace kestrel::nn {

bool conv_bf16_supported() {
  // Asked for every layer of every frame: the CPU is read once.
  static const bool supported = [] {
    __builtin_cpu_init();
    return isa_supported(Isa::avx512) && __builtin_cpu_supports("avx512bf16");
  }();
  return supported;
}

const ConvKernels& conv_kernels(Isa isa, bool bf16) {
  require_supported(isa);
  if (bf16 && isa == Isa::avx512 && conv_bf16_supported()) return conv_kernels_avx512_bf16();
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
