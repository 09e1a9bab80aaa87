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
#include "upscale/reconstruct.h"

namespace kestrel::upscale::nsrr {

using nn::Dnn;
using nn::Net;

constexpr float kReweightMax = 10.0f;
/// The blend's candidates (nsrr.blend_logits): the base, every frame's samples in the (2 r + 1)^2
/// output pixels around a pixel (r = kBlendRadius for the current frame, `previous_radius` <=
/// kBlendRadius for the `previous` others), and the history.
constexpr int blend_logits(int previous, int previous_radius = kBlendRadius) {
  return 2 + (2 * kBlendRadius + 1) * (2 * kBlendRadius + 1) +
         previous * (2 * previous_radius + 1) * (2 * previous_radius + 1);
}
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
  // Separable: sample_at[Y W + X] = row_at[Y] w + col_at()[X] where both are >= 0, else -1
  // (the low-res row and column whose samples land in output row Y and column X); col_at()
  // readable for X in [-kColPad, W + kColPad), -1 off the image.
  static constexpr size_t kColPad = kMaxLanes;
  std::vector<int32_t> col_padded, row_at;
  const int32_t* col_at() const { return col_padded.data() + kColPad; }
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
/// (X + 1/2) / f - j + 1/2, pixel centres at i + 1/2, edges clamped): the first of the blend's
/// candidates. The column taps are the same on every row: tabled once per frame.
class BilinearBase {
 public:
  void build(const Frame& cur, int f, int W) {
    fr_ = &cur, f_ = float(f);
    i0_.resize(size_t(W)), i1_.resize(size_t(W)), tx_.resize(size_t(W));
    for (size_t X = 0; X < size_t(W); ++X) {
      const float xf = (float(X) + 0.5f) / f_ - cur.jx;
      const int x0 = floor_int(xf);
      tx_[X] = xf - float(x0);
      i0_[X] = clampi(x0, 0, cur.w - 1), i1_[X] = clampi(x0 + 1, 0, cur.w - 1);
    }
  }
  /// The blend's view of the base at output row Y (reconstruct.h: BlendArgs).
  void set(BlendArgs& a, size_t Y) const {
    const float yf = (float(Y) + 0.5f) / f_ - fr_->jy;
    const int y0 = floor_int(yf);
    a.y = fr_->y.data(), a.n = size_t(fr_->w) * size_t(fr_->h);
    a.j0 = size_t(clampi(y0, 0, fr_->h - 1)) * size_t(fr_->w);
    a.j1 = size_t(clampi(y0 + 1, 0, fr_->h - 1)) * size_t(fr_->w), a.ty = yf - float(y0);
    a.i0 = i0_.data(), a.i1 = i1_.data(), a.tx = tx_.data();
  }

 private:
  const Frame* fr_ = nullptr;
  float f_ = 2;
  std::vector<int> i0_, i1_;
  std::vector<float> tx_;
};

/// The kernel-predicting reconstruction both members end with (nsrr.blend), into the output
/// frame (W x H, linear RGB). row_logits(Y, l) writes output row Y's K = blend_logits(previous,
/// previous_radius) logits, planar (logit c of pixel X at l[c W + X]): c = 0 weighs `base`,
/// then per frame t-k in order the y of its samples at output pixels (X + dx, Y + dy), |dx|,
/// |dy| <= r_k (kBlendRadius for the current frame, previous_radius for the others), row by
/// row (frame 0's sample_at, then the warp's src), a candidate where that pixel is on the image
/// and holds a sample; c = K - 1 the history (`hist`: its y, 3 planes of W x H).
/// The output is the softmax over the candidates of their y, a convex combination, back from
/// y. `base` must be built for this frame. The current frame's candidates are read from its y
/// through its column and row tables, previous frames' at radius 0 through the warp's indices;
/// previous frames at a larger radius are zero-upsampled first into planes (reconstruct.h:
/// ZeroUpArgs) kept between frames. The per-pixel loops are reconstruct.h's kernels of
/// default_isa().
class Blend {
 public:
  template <class RowLogits>
  void run(const BilinearBase& base, const float* hist, const Window& window,
           const std::vector<int32_t>& src, int previous, int previous_radius, int W, int H,
           FloatImage& out, RowLogits&& row_logits) {
    constexpr int r = kBlendRadius;
    const int frames = std::min(int(window.size()), previous + 1);
    const size_t N = size_t(W) * size_t(H), n = size_t(window[0].w) * size_t(window[0].h);
    const size_t plane = (size_t(W) + 2 * size_t(r)) * (size_t(H) + 2 * size_t(r));
    // The previous frames in planes, unless they are read where they are too.
    const size_t planar = previous_radius == 0 ? 0 : size_t(previous);
    if (W != W_ || H != H_ || planes_.size() < 4 * plane * planar) {
      // The border is never written: zeros, no samples.
      planes_.assign(4 * plane * planar, 0.0f);
      W_ = W, H_ = H;
    }
    const UpscaleKernels& kern = upscale_kernels(default_isa());
    BlendArgs b{};
    for (int k = 1; k < frames; ++k) {  // (the current frame is read where it is)
      const int32_t* at = src.data() + size_t(k - 1) * N;
      if (previous_radius == 0) {
        // One candidate a pixel: read where it is too (no planes written and read back).
        b.at[k] = at, b.ylow[k] = window[size_t(k)].y.data();
        continue;
      }
      const ZeroUpArgs z{
          at, window[size_t(k)].y.data(), n, planes_.data() + 4 * plane * size_t(k - 1), W, H, r};
      parallel_for(0, size_t(H), 8,
                   [&](size_t r0, size_t r1) { kern.zero_upsample(z, int(r0), int(r1)); });
      b.z[k] = z.z;
    }
    b.col_at = window[0].col_at(), b.row_at = window[0].row_at.data(), b.w = window[0].w;
    b.W = W, b.H = H, b.r = r, b.frames = previous + 1, b.hist_plane = N;
    for (int k = 0; k <= previous; ++k) b.rk[k] = k == 0 ? r : previous_radius;
    const size_t K = size_t(blend_logits(previous, previous_radius));
    out.width = W, out.height = H, out.channels = 3;
    out.pixels.resize(3 * N);
    parallel_for(0, size_t(H), 8, [&](size_t r0, size_t r1) {
      std::vector<float> l(K * size_t(W));
      BlendArgs a = b;
      a.logits = l.data();
      for (size_t Y = r0; Y < r1; ++Y) {
        row_logits(Y, l.data());
        base.set(a, Y);
        a.hist = hist + Y * size_t(W);
        a.Y = int(Y), a.out = &out.pixels[3 * Y * size_t(W)];
        kern.blend_row(a);
      }
    });
  }

 private:
  std::vector<float> planes_;
  int W_ = 0, H_ = 0;
};

/// What both members hold: their layers (loaded and checked from the weights file), the oneDNN
/// engine, the window of frames, the bilinear base and the history's y.
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
  Blend blend;
  std::vector<float> hist;  // the history's y (nsrr.history_sequence): 3 planes of W x H

  /// hist from the learned TAAU's output (linear, channels last), cleaned as a frame's colour.
  void history_y(const FloatImage& history);

 private:
  size_t parameters_ = 0;
};

}  // namespace kestrel::upscale::nsrr
