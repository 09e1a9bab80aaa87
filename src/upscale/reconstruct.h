// The upsampler's per-pixel stages (scripts/upscale/model.py: the inputs, their statistics,
// the history test, the network's features and the reconstruction step), compiled once per
// instruction set (reconstruct_*.cpp include prepare.inl and reconstruct.inl with their own
// flags) and picked per frame by default_isa(), the choice --isa / KESTREL_ISA /
// set_default_isa make.
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

constexpr float kMinDepth = 1e-3f, kMaxMotion = 65536.0f;
// History is dropped where no previous depth around the reprojected position is within this
// fraction of the current depth (the denoisers' test) plus the depth's slope: a disocclusion.
constexpr float kDisocclusion = 0.1f;

// A frame's low-resolution images (w x h, n = w h pixels), planar: channel c of an image at
// image + c n, every buffer padded by kMaxLanes floats so a vector load at any pixel stays
// inside it.
constexpr int kMaxLanes = 16;
struct LowRes {
  int w = 0, h = 0;
  size_t n = 0;
  float* y = nullptr;       // 3: the colour in the tone-mapped space c / (1 + luma(c))
  float* depth = nullptr;   // 1 (1 where the input has none)
  float* motion = nullptr;  // 2: the input's motion, finite and clamped
  float* mdil = nullptr;    // 2: the motion of the least depth in the 3x3 window
  float* mu = nullptr;      // 3: the 3x3 mean of y
  float* sigma = nullptr;   // 3: its standard deviation
  float* keep = nullptr;    // 1: 1 where the history shows this pixel's surface (disocclusion)
  float* feat = nullptr;    // 8: the network's low-resolution features (neural only)
};

// The input stage: colour (channels-last, 3), depth (1 channel or null), motion (mc channels,
// 2 or 3, or null) into y, depth and motion; rows [r0, r1).
struct InputArgs {
  const float *color, *depth, *motion;
  int mc;
  LowRes lr;
};
// The history test (model.keep_history) and the network's features (model.features) read
// the previous frame's depth (low resolution) and the history (three planes of W x H).
struct HistoryArgs {
  LowRes lr;
  const float *prev_depth, *hist;
  int W, H, f;
  float jx, jy, prev_jx, prev_jy;
  bool history;
};

// The per-output-pixel reconstruction (model.step), rows [r0, r1). The history (hist, read,
// and next, written) is three planes of W x H (R, G, B), so a vector of neighbouring output
// pixels reads each Catmull-Rom tap with one load; grid is channels-last (3 per cell), out
// channels-last.
struct Recon {
  LowRes lr;
  const float *grid, *hist;
  float *next, *out;
  const Axis *ax, *ay;
  const GridAxis *gx, *gy;
  int W, H, gw, f;
  bool history;
};

// The nsrr family's blend (scripts/upscale/nsrr.py: blend; nsrr_parts.h: Blend).
// A frame's samples at the output resolution W x H are four planes (y, and 1 where the pixel
// holds a sample, else 0) of (W + 2 r) x (H + 2 r), the image at offset (r, r) in a border of
// no samples; zero_upsample writes rows [r0, r1) of the image from the frame's sample map.
constexpr float kBlendYMax = 0.999f;
constexpr int kBlendMaxFrames = 4;
/// The current frame's candidates are its samples in the (2 kBlendRadius + 1)^2 output pixels
/// around a pixel (nsrr.blend_logits).
constexpr int kBlendRadius = 1;
struct ZeroUpArgs {
  const int32_t* at;  // W x H: the low-resolution pixel whose sample an output pixel holds, -1
  const float* y;     // the frame's y, 3 planes of n
  size_t n;
  float* z;  // the four planes, each (W + 2 r) (H + 2 r)
  int W, H, r;
};
// One output row Y: K = 2 + sum over frames of (2 r_k + 1)^2 logits per pixel (r_k <= r, the
// border), planar (logit c of pixel X at logits[c W + X]): c = 0 weighs the base, then per frame
// k in order its samples at (X + dx, Y + dy), |dx|, |dy| <= r_k, row by row, and c = K - 1 the
// history (the row's y, 3 planes of W at hist[c hist_plane]).
// The base (nsrr.bilinear_base) is the current frame's y (3 planes of n, padded by kMaxLanes)
// at rows j0, j1 (offsets, weight ty of j1) and columns i0[X], i1[X] (non-decreasing, weight
// tx[X] of i1).
struct BlendArgs {
  // The current frame (k = 0) read where it is: its y is the base's, its samples tabled by
  // column (col_at[X] for X in [-kBlendRadius, W + kBlendRadius), -1 off the image) and row
  // (row_at, H entries): output pixel (X, Y) holds low-res pixel (col_at[X], row_at[Y]) where both
  // are >= 0; w the frame's width.
  const int32_t *col_at, *row_at;
  int w;
  // The previous frames (k >= 1):
  const float* z[kBlendMaxFrames];  // per frame of the window (ZeroUpArgs::z), null: none
  // Or, for a frame whose radius is 0, its sample map (ZeroUpArgs::at) and its y (3 planes of
  // n, padded by kMaxLanes): its candidate read where it is, not from planes.
  const int32_t* at[kBlendMaxFrames];
  const float* ylow[kBlendMaxFrames];
  const float* logits;
  const float* hist;  // the history's y at row Y (its 3 planes hist_plane apart)
  size_t hist_plane;
  const float* y;  // the base's frame
  size_t n, j0, j1;
  float ty;
  const int *i0, *i1;
  const float* tx;
  float* out;  // W x 3: the row's linear colour
  int W, H, r, frames, Y;
  int rk[kBlendMaxFrames];  // per frame: the radius of its candidates, <= r
};

// The upsampler's per-pixel stages for one instruction set, each over rows [r0, r1).
struct UpscaleKernels {
  void (*input)(const InputArgs& a, int r0, int r1);
  void (*stats)(const LowRes& lr, int r0, int r1);             // mu, sigma, mdil
  void (*disocclusion)(const HistoryArgs& a, int r0, int r1);  // keep
  void (*features)(const HistoryArgs& a, int r0, int r1);      // feat
  void (*reconstruct)(const Recon& a, int r0, int r1);
  void (*zero_upsample)(const ZeroUpArgs& a, int r0, int r1);  // nsrr, nsrr-rt
  void (*blend_row)(const BlendArgs& a);
};
const UpscaleKernels& upscale_kernels_sse2();
const UpscaleKernels& upscale_kernels_avx2();
const UpscaleKernels& upscale_kernels_avx512();
/// The kernels of an ISA (Error if this CPU lacks it).
const UpscaleKernels& upscale_kernels(Isa isa);

}  // namespace kestrel::upscale
