// The convolution kernels every network runs (denoiser, upsampler), compiled once per
// instruction set (conv_<isa>.cpp include conv.inl with their own -m flags) and picked by
// the caller's ISA: default_isa() for a network's own code, the file's ISA for per-ISA code.
#pragma once
#include <vector>

#include "kestrel/isa.h"
#include "nn/weights.h"

namespace kestrel::nn {

/// A 3x3 (or 1x1) convolution, zero padded, on channels-last images: in [h][w][cin],
/// weights [ky][kx][cin][cout], out [h][w][cout], cout a multiple of 16.
struct ConvArgs {
  const float* in = nullptr;
  const float* weights = nullptr;
  const float* bias = nullptr;
  float* out = nullptr;
  int width = 0, height = 0, cin = 0, cout = 0, ksize = 3;
  bool relu = true;
};

struct ConvKernels {
  /// One convolution on a channels-last image (w x h x l.cin) -> out (w x h x l.cout), on the
  /// thread pool; scratch holds the zero-padded input.
  void (*conv)(const ConvLayer& l, const std::vector<float>& in, int w, int h,
               std::vector<float>& out, bool relu, std::vector<float>& scratch);
  const char* isa;
  bool bf16 = false;  ///< inputs and weights rounded to bf16 (else f32 throughout)
};

const ConvKernels& conv_kernels_sse2();
const ConvKernels& conv_kernels_avx2();
const ConvKernels& conv_kernels_avx512();
/// bf16 inputs and weights, f32 sums (vdpbf16ps): only where conv_bf16_supported().
const ConvKernels& conv_kernels_avx512_bf16();
/// Whether this CPU runs the bf16 kernel (AVX-512 with AVX512_BF16).
bool conv_bf16_supported();
/// The kernels of an ISA (Error when this CPU lacks it); with `bf16`, the bf16 kernel where
/// the ISA is avx512 and the CPU has it (else the ISA's f32 kernel).
const ConvKernels& conv_kernels(Isa isa, bool bf16 = false);

}  // namespace kestrel::nn
