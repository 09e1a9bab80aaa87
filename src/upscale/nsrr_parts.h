// What the two members of the nsrr family (src/upscale/nsrr.cpp: `nsrr`, after Xiao et al.
// 2020; src/upscale/nsrr_rt.cpp: `nsrr-rt`, the real-time member) share: a window of cleaned
// low-resolution frames, zero-upsampling, the accumulated backward warp, and the oneDNN
// networks they are built from. scripts/upscale/nsrr.py is the reference definition.
// Included by those two files only (oneDNN's header is heavy).
#pragma once
#include <algorithm>
#include <cstdint>
#include <cstring>
#include <deque>
#include <oneapi/dnnl/dnnl.hpp>
#include <unordered_map>
#include <vector>

#include "core/parallel.h"
#include "kestrel/image.h"
#include "kestrel/upscale.h"
#include "nn/dnn.h"
#include "nn/weights.h"
#include "upscale/nsrr.h"
#include "upscale/nsrr_warp.h"

namespace kestrel::upscale::nsrr {

using nn::Dnn;
using nn::Net;

constexpr float kReweightMax = 10.0f, kYMax = 0.999f;
constexpr char kMagic[9] = "KSTRLNSR";

// Inline: they run per output pixel.
inline float luma(const float* c) {
  return 0.2126f * c[0] + 0.7152f * c[1] + 0.0722f * c[2];
}
inline int clampi(int v, int lo, int hi) {
  return v < lo ? lo : (v > hi ? hi : v);
}
inline int floor_int(float x) {  // |x| < 2^31
  const int i = int(x);
  return i - (float(i) > x);
}
/// One low-resolution frame of the window, cleaned as nsrr.clean does: planar y = c / (1 +
/// L(c)) (3), depth (1), motion (2), and where its samples land at the output resolution.
struct Frame {
  int w = 0, h = 0;
  float jx = 0.5f, jy = 0.5f;
  std::vector<float> y, depth, motion;
  std::vector<int32_t> sample_at;  // output pixel -> the low-res pixel whose sample it holds, -1
};

/// The window [current, previous, ...] of at most `previous` + 1 frames.
class Window {
 public:
  /// Cleans `in` into a new current frame (dropping the oldest beyond `previous` + 1);
  /// returns the depth scale s of nsrr.depth_scale (the mean non-sky depth, 1 if none).
  float push(const UpscaleInput& in, int factor, int previous);
  void clear() { frames_.clear(); }
  size_t size() const { return frames_.size(); }
  const Frame& operator[](size_t k) const { return frames_[k]; }
  /// src[(k - 1) W H + q], k = 1..previous: the low-res pixel of frame t-k at output pixel q
  /// after the accumulated backward warp (nsrr.warp_positions + gather_nearest), -1 for none.
  void warp(int factor, int W, int H, int previous, std::vector<int32_t>& src) const;

 private:
  std::deque<Frame> frames_;
};

/// The current frame's y bilinearly upsampled (nsrr.bilinear_base: model.bilinear_at at
/// (X + 1/2) / f - j + 1/2, pixel centres at i + 1/2, edges clamped): what both networks predict
/// a correction of. The column taps are the same on every row: tabled once per frame.
class BilinearBase {
 public:
  struct Row {
    size_t j0, j1;
    float ty;
  };
  void build(const Frame& cur, int f, int W) {
    fr_ = &cur, f_ = float(f);
    i0_.resize(size_t(W)), i1_.resize(size_t(W)), tx_.resize(size_t(W));
    for (size_t X = 0; X < size_t(W); ++X) {
      const float xf = (float(X) + 0.5f) / f_ - cur.jx;
      const int x0 = floor_int(xf);
      tx_[X] = xf - float(x0);
      i0_[X] = uint32_t(clampi(x0, 0, cur.w - 1)), i1_[X] = uint32_t(clampi(x0 + 1, 0, cur.w - 1));
    }
  }
  Row row(size_t Y) const {
    const float yf = (float(Y) + 0.5f) / f_ - fr_->jy;
    const int y0 = floor_int(yf);
    return {size_t(clampi(y0, 0, fr_->h - 1)) * size_t(fr_->w),
            size_t(clampi(y0 + 1, 0, fr_->h - 1)) * size_t(fr_->w), yf - float(y0)};
  }
  /// y[c] += the base at output pixel (X, r's row).
  void add(const Row& r, size_t X, float y[3]) const {
    const float tx = tx_[X], ty = r.ty;
    const size_t i0 = i0_[X], i1 = i1_[X], n = size_t(fr_->w) * size_t(fr_->h);
    for (size_t c = 0; c < 3; ++c) {
      const float* p = fr_->y.data() + c * n;
      y[c] += (1 - ty) * (1 - tx) * p[r.j0 + i0] + (1 - ty) * tx * p[r.j0 + i1] +
              ty * (1 - tx) * p[r.j1 + i0] + ty * tx * p[r.j1 + i1];
    }
  }

 private:
  const Frame* fr_ = nullptr;
  float f_ = 2;
  std::vector<uint32_t> i0_, i1_;
  std::vector<float> tx_;
};

/// y (clamped to [0, kYMax]) back to linear colour, as model.from_y.
inline void from_y(const float y_in[3], float* out) {
  float y[3];
  for (size_t c = 0; c < 3; ++c) y[c] = std::clamp(y_in[c], 0.0f, kYMax);
  const float d = std::max(1.0f - luma(y), 1e-3f);
  for (size_t c = 0; c < 3; ++c) out[c] = y[c] / d;
}

/// The output frame (W x H, linear RGB): at each pixel a network's correction (correction(X,
/// Y, y) writes it) plus `base`, back from y. `base` must be built for this frame.
template <class Correction>
void write_output(const BilinearBase& base, int W, int H, FloatImage& out,
                  Correction&& correction) {
  out.width = W, out.height = H, out.channels = 3;
  out.pixels.resize(3 * size_t(W) * size_t(H));
  parallel_for(0, size_t(H), 8, [&](size_t r0, size_t r1) {
    for (size_t Y = r0; Y < r1; ++Y) {
      const BilinearBase::Row row = base.row(Y);
      for (size_t X = 0; X < size_t(W); ++X) {
        float y[3];
        correction(X, Y, y);
        base.add(row, X, y);
        from_y(y, &out.pixels[3 * (Y * size_t(W) + X)]);
      }
    }
  });
}

/// What both members hold: their layers (loaded and checked from the weights file), the oneDNN
/// engine, the window of frames and the bilinear base.
class Member : public NsrrNetwork {
 public:
  void reset() override { window.clear(); }
  size_t parameters() const override { return parameters_; }
  bool bf16() const override { return dnn.bf16; }

 protected:
  /// Throws Error naming the file (nn::load_layers) for a missing, corrupt or foreign file.
  Member(const std::string& weights, int factor, bool bf16, uint32_t architecture,
         const std::vector<nn::LayerSpec>& specs, const char* what);
  /// Dnn::conv of layer `layer` (the index of its tensors in the weights file).
  dnnl::memory conv(Net& net, dnnl::memory in, size_t layer, bool relu, bool last,
                    const dnnl::post_ops* extra = nullptr,
                    dnnl::memory::format_tag last_tag = dnnl::memory::format_tag::nchw) {
    return dnn.conv(net, in, layers[layer], relu, last, extra, last_tag);
  }
  int f = 2;
  std::vector<nn::ConvLayer> layers;
  Dnn dnn;
  Window window;  // [current, previous, ...]
  BilinearBase base;

 private:
  size_t parameters_ = 0;
};

}  // namespace kestrel::upscale::nsrr
