// The neural denoiser's weights and per-frame network (see scripts/denoise/model.py, the
// reference definition, and docs/denoiser.md).
#pragma once
#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "nn/weights.h"

namespace kestrel::denoise {

/// The first line (of 64 bytes) of the next Planes' channel 0 within a 4 KiB page; see Planes.
size_t next_planes_offset();

/// Planar float images of one frame, padded to multiples of 8 (edge replicated).
///
/// Laid out so the same pixel of different channels, and of different Planes, falls in
/// different L1 cache sets. Planes a multiple of 4 KiB apart (1280 x 720 floats are exactly
/// 900 pages) put the same pixel of every channel in one set: a filter tap reading ten
/// planes at three rows then evicts its own lines (and loads wait on unrelated stores 4 KiB
/// away), which measured the neural filter at 2-2.5x its time on a 1288 x 720 frame. So
/// channel c starts c * stride floats after channel 0, the stride a whole number of lines
/// that is 37 modulo 64 (channels 0-12 then start 3 or more lines apart in the 64 sets), and
/// each Planes starts channel 0 at its own line of the page (`offset`).
struct Planes {
  int width = 0, height = 0;
  std::vector<float> data;  ///< channel c at data[offset + c * stride]; zeros between
  int channels = 0;
  size_t stride = 0;                      ///< floats from one channel to the next
  size_t offset = 0;                      ///< floats before channel 0
  int image_width = 0, image_height = 0;  ///< the image inside the padding (0: all of it)
  Planes() = default;
  Planes(int w, int h, int c)
      : width(w),
        height(h),
        channels(c),
        stride(plane_stride(w, h)),
        offset(next_planes_offset() * 16) {
    data.assign(offset + stride * size_t(c), 0.0f);
  }
  float* ch(int c) { return data.data() + offset + size_t(c) * stride; }
  const float* ch(int c) const { return data.data() + offset + size_t(c) * stride; }
  static size_t plane_stride(int w, int h) {
    const size_t lines = (size_t(w) * size_t(h) + 15) / 16;
    return (lines + (37 + 64 - lines % 64) % 64) * 16;
  }
};

using nn::ConvLayer;
using nn::LayerSpec;
using nn::load_layers;

struct NeuralWeights {
  ConvLayer enc1, enc2, enc3, dec1, head;
  size_t parameters = 0;
  /// Reads a weights file (format v1, docs/denoiser.md); throws Error naming the file.
  static NeuralWeights load(const std::string& path);
};

constexpr int kFeatures = 18;
constexpr int kLevels = 4;
constexpr int kOutputs = 2 + 4 * kLevels;  ///< alpha, kLevels x (sc, sn, sz, beta), kappa
/// Irradiance after the first filter level 0-2, depth 3, length 4, black flag 5.
constexpr int kStateChannels = 6;
constexpr float kMaxHistory = 32.0f;    ///< the longest history (frames) the state counts
constexpr float kMinNormalStop = 2.0f;  ///< sn >= 2, sz >= 3: geometry edges always hold
constexpr float kMinDepthStop = 3.0f;
constexpr float kHistoryAllowance = 4.0f;  ///< never cut as a firefly: up to 4x the history
/// The output's last step takes a history as evidence of a bright pixel from this length on
/// (frames): a history of one frame is one sample, no more than the pixel's own.
constexpr float kHistoryEvidence = 2.0f;
/// The history's upper clamp reaches this many quarter-res cells around a pixel's (5x5: a
/// 20x20 window), its lower clamp one (3x3).
constexpr int kHistoryMaxReach = 2;
/// The fireflies' cut energy spread over their window raises its mean at most this much (x the
/// window's cut mean).
constexpr float kRedistributeCap = 1.0f;
constexpr float kAlbedoEps = 0.01f;
constexpr float kBlackAlbedo = 0.02f;  ///< below this in every channel: no demodulation
/// Whether an albedo is (nearly) black: left undemodulated by every denoiser.
inline bool black_albedo(float a0, float a1, float a2) {
  return a0 < kBlackAlbedo && a1 < kBlackAlbedo && a2 < kBlackAlbedo;
}
constexpr float kDisoccluded = 0.1f;  ///< relative depth change that rejects the history
constexpr float kMinDepth = 1e-3f;

/// Buffers reused from frame to frame (no allocation or page faults once warm).
struct Workspace {
  /// The CNN's convolutions in bf16 where the CPU has the kernel (nn::conv_kernels), else f32.
  bool bf16 = false;
  Planes x, xlin, demod, yw, xi, xo, lg, lg2, out, next_state;
  std::vector<float> bound, bound3, mu, mu3, cells, cut3, top3;
  std::vector<uint8_t> black_rows;  ///< per row: any pixel with black flag 1
  std::vector<float> zw, nw, kw, valid, zc, feat, e1, pooled, e2, e3, cat, d1, o, act, padded,
      hrows;
};

/// Milliseconds per stage of the last frame (KESTREL_DENOISE_PROFILE=1 prints them).
struct StageTimes {
  double prepare = 0, features = 0, cnn = 0, temporal = 0, filter = 0, output = 0;
};

/// Inputs of one frame as planes (padded): color 0-2, albedo 3-5, normal 6-8, depth 9,
/// roughness 10, motion 11-12. state: accumulated irradiance after the first filter level 0-2,
/// depth 3, history length 4, black flag 5 (1: not demodulated; empty on the first frame).
/// Returns the output colour planes (3, in ws.out) and replaces state.
const Planes& run_network(const NeuralWeights& w, const Planes& in, Planes& state, bool recurrent,
                          Workspace& ws, StageTimes* times = nullptr);

}  // namespace kestrel::denoise
