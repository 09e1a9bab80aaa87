// The denoiser's hot loops, compiled once per instruction set (kernels_*.cpp include
// kernels.inl with their own -m flags) and picked at run time by the host's CPU.
#pragma once
#include <cstddef>
#include <vector>

#include "denoise/neural.h"

namespace kestrel::denoise {

/// One a-trous level of the neural filter on planar images (width x height each):
/// out_c = x_c + beta * (sum_q h_q w_q x_c(q) / sum_q h_q w_q - x_c), 3x3 taps at
/// +-dilation, clamped at the borders, w_q = exp(-sc |g - g_q|^2 - sn max(0, n.n - n.n_q)
/// - sz |z - z_q| / max(z, 1e-3)). The strengths sc, sn, sz, beta come from quarter-res maps
/// already upsampled horizontally (`rows` x width each, `param[k]`); each output row lerps two
/// of those rows (PyTorch's bilinear x4), fused into the filter so no full-res map is written.
struct AtrousArgs {
  const float* x[3] = {};  ///< linear irradiance, filtered
  const float* g[3] = {};  ///< its log(1 + x): the colour edge-stopping guide
  const float* n[3] = {};
  const float* z = nullptr;
  /// 1 where the pixel is not demodulated (black albedo): taps mix only like with like.
  const float* black = nullptr;
  const uint8_t* black_rows = nullptr;  ///< per row: whether it holds a black pixel
  const float* param[4] = {};  ///< sc, sn, sz, beta: horizontally upsampled quarter-res rows
  int param_rows = 0;
  float* out[3] = {};
  float* gout[3] = {};  ///< if set: log(1 + max(out, 0)), the next level's guide
  int width = 0, height = 0, dilation = 1;
};

struct KernelTable {
  const Planes& (*network)(const NeuralWeights& w, const Planes& in, Planes& state, bool recurrent,
                           Workspace& ws, StageTimes* times);
  const char* isa;
};

const KernelTable& kernels_sse2();
const KernelTable& kernels_avx2();
const KernelTable& kernels_avx512();
const KernelTable& host_kernels();

}  // namespace kestrel::denoise
