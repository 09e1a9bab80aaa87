// Network weights as kestrel stores and runs them: convolution layers (weights re-laid for
// the conv kernels) read from a kestrel weights file.
#pragma once
#include <cstdint>
#include <string>
#include <vector>

namespace kestrel::nn {

struct ConvLayer {
  int cin = 0, cout = 0, ksize = 3;  ///< cout: stored outputs, a multiple of 16
  int outputs = 0;                   ///< the layer's real outputs (<= cout; the rest are zero)
  std::vector<float> weights;        ///< [ky][kx][cin][cout]
  std::vector<float> bias;
};

/// One convolution of a weights file: its tensor names are name.weight [cout][cin][k][k] and
/// name.bias [cout].
struct LayerSpec {
  const char* name;
  int cout, cin, ksize;
};

/// Reads a kestrel weights file (format v1, docs/denoiser.md): `magic`, version 1,
/// `architecture`, exactly the tensors of `specs` in order, the FNV-1a 64 checksum. `what`
/// names the network in errors. Throws Error naming the file and the problem.
std::vector<ConvLayer> load_layers(const std::string& path, const char (&magic)[9],
                                   uint32_t architecture, const std::vector<LayerSpec>& specs,
                                   const char* what);

}  // namespace kestrel::nn
