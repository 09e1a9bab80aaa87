// The upsampler's per-output-pixel reconstruction (scripts/upscale/model.py step), compiled
// once per instruction set (reconstruct_*.cpp include reconstruct.inl with their own flags)
// and picked per call by default_isa(), the choice --isa / KESTREL_ISA / set_default_isa make.
#pragma once
#include <cstdint>
#include <vector>

#include "kestrel/isa.h"

namespace kestrel::upscale {

// Per output column (or row): the nearest sample's index (non-decreasing), its three
// Gaussian weights (offsets -1, 0, +1: w[0], w[1], w[2]) and the offset to the nearest
// sample, in low-resolution pixels.
struct Axis {
  std::vector<int> i0;
  std::vector<float> w[3];
  std::vector<float> d0;
  void build(int out, int in, int f, float jitter,
             float sharpness);  // upscale.cpp (not inline: no ISA flags)
};

// Bilinear taps of the parameter grid (pixel centres at 4k + 2 in output pixels; a and b
// non-decreasing).
struct GridAxis {
  std::vector<int> a, b;
  std::vector<float> t;
  void build(int out, int grid);
};

// The per-output-pixel reconstruction (model.step), rows [r0, r1), by reconstruct_for(isa).
// Low-resolution images (y, mu, sigma, grid: 3 channels; mdil: 2) are channels-last; the
// history (hist, read, and next, written) is three planes of W x H (R, G, B), so a vector of
// neighbouring output pixels reads each Catmull-Rom tap with one load; out is channels-last.
struct Recon {
  const float *y, *mdil, *mu, *sigma, *grid, *hist;
  const uint8_t* keep;  // per low-resolution pixel: its history sample shows the same surface
  float *next, *out;
  const Axis *ax, *ay;
  const GridAxis *gx, *gy;
  int w, h, W, H, gw, f;
  bool history;
};

using ReconstructFn = void (*)(const Recon& a, int r0, int r1);
ReconstructFn reconstruct_sse2();
ReconstructFn reconstruct_avx2();
ReconstructFn reconstruct_avx512();
/// The reconstruction of an ISA (Error if this CPU lacks it).
ReconstructFn reconstruct_for(Isa isa);

}  // namespace kestrel::upscale
