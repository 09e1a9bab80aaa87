// The nsrr family's per-output-pixel loops, as a scalar loop and an AVX-512 one
// (nsrr_warp_avx512.cpp) that compute the same bits; *_for(default_isa()) picks.
//
// One output row of the accumulated backward warp (nsrr.warp_positions + gather_nearest),
// one step k: the positions advance by the motion of frame t-k+1 and the row's samples of
// frame t-k are gathered.
#pragma once
#include <cstddef>
#include <cstdint>
#include <cstring>

#include "kestrel/isa.h"

namespace kestrel::upscale::nsrr {

/// bf16 by round-to-nearest-even (finite x), as oneDNN's reorders convert; and back.
inline uint16_t float_to_bf16(float x) {
  uint32_t u;
  std::memcpy(&u, &x, 4);
  u += 0x7FFFu + ((u >> 16) & 1u);
  return uint16_t(u >> 16);
}
inline float bf16_to_float(uint16_t b) {
  const uint32_t u = uint32_t(b) << 16;
  float x;
  std::memcpy(&x, &u, 4);
  return x;
}
/// A grid element (float or bf16 as uint16_t) read and written as float.
inline float load(float v) {
  return v;
}
inline float load(uint16_t v) {
  return bf16_to_float(v);
}
inline void store(float& d, float v) {
  d = v;
}
inline void store(uint16_t& d, float v) {
  d = float_to_bf16(v);
}

struct WarpRow {
  const float *mx, *my;  // frame t-k+1's motion (low resolution, planar x then y)
  // Frame t-k's samples: output pixel (X, Y) holds low-res pixel (col_at[X], row_at[Y])
  // where both are >= 0 (nsrr_parts.h: Frame), none otherwise.
  const int32_t *col_at, *row_at;
  int w, h, W, H;  // low and output resolution
  float f, inv_f;  // the factor (2 or 4: inv_f exact)
};

/// pos: W interleaved (x, y) output-pixel positions, advanced in place; out: W indices, -1
/// where the advanced position is off screen.
using WarpRowFn = void (*)(const WarpRow& a, float* pos, int32_t* out);
void warp_row_scalar(const WarpRow& a, float* pos, int32_t* out);
void warp_row_avx512(const WarpRow& a, float* pos, int32_t* out);
WarpRowFn warp_row_for(Isa isa);

/// nsrr-rt's input grid (channels last, cells of 4 x 4 output pixels): channel (4 k + c) 16 +
/// sub of cell (gx, gy) is x[c] = [y, d(z)][c] of frame t-k at output pixel (4 gx + sub % 4,
/// 4 gy + sub / 4), 0 where that pixel holds no sample; channel kHistory + 16 c + sub the
/// history's y[c] there (0 off the image); the last channel `last`.
struct GridFill {
  static constexpr int kFrames = 3, kX = 4, kHistory = kFrames * kX * 16;
  static constexpr int kChannels = kHistory + 3 * 16 + 1;
  const int32_t* at[kFrames];  // per frame: output pixel -> low-res pixel, -1
  int frames;                  // frames in the window (the rest read as no sample)
  const float* packed;         // frame k's x of low-res pixel i at packed[4 (k n + i)]
  size_t n;                    // low-res pixels per frame
  const float* hist;           // the history's y: 3 planes of W x H
  int W, H, Gw;
  float last;
  bool bf16;   // grid elements bf16 (uint16_t, round to nearest even) or float
  void* grid;  // Gw x Gh cells of kChannels
};
using GridRowsFn = void (*)(const GridFill& a, size_t gy0, size_t gy1);
void grid_rows_scalar(const GridFill& a, size_t gy0, size_t gy1);
void grid_rows_avx512(const GridFill& a, size_t gy0, size_t gy1);
GridRowsFn grid_rows_for(Isa isa);

}  // namespace kestrel::upscale::nsrr
