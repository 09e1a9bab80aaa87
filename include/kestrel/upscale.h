// Temporal upsampling of jittered low-resolution frames: kestrel's learned TAAU (a small CNN
// at 1/4 of the output resolution predicting, per pixel, how much to trust the reprojected
// history: its blend weight, the width of its neighbourhood clamp and how fast the current
// frame's weight falls off with the distance to its samples) and three baselines: a
// TAAU-like upsampler (the same reconstruction with constants), bicubic (Catmull-Rom) and
// bilinear of the current frame; and `nsrr`, neural supersampling after Xiao et al. 2020 (the
// current and three previous frames' features zero-upsampled, warped by the accumulated motion,
// reweighted and reconstructed by a U-Net at the output resolution: a quality mode, far from
// real time) and its real-time member `nsrr-rt`; both blend those samples with the output of the
// learned TAAU, which runs beside them (default_upscaler_weights(neural)). See docs/upscaler.md.
#pragma once
#include <memory>
#include <optional>
#include <string>
#include <string_view>

#include "kestrel/image.h"

namespace kestrel {

enum class UpscaleMethod { neural, taau, bicubic, bilinear, nsrr, nsrr_rt };
const char* upscale_method_name(UpscaleMethod m);
std::optional<UpscaleMethod> upscale_method_from_name(std::string_view name);
/// Every method's name, separated by `sep` (for help texts and errors).
std::string upscale_method_list(const char* sep = ", ");

/// One low-resolution frame (pointers, not owned). colour (3 channels, linear HDR) is
/// point-sampled: pixel (i, j) holds the sample at (i + jitter_x, j + jitter_y), jitter in
/// [0, 1] (kestrel's Frame::jitter_x/y, frame_jitter in render.h; RenderSettings::fixed_jitter
/// for many samples).
/// depth (1 channel; null = 1) and motion (2 or 3 channels, low-resolution pixels, "p +
/// motion = where the surface was in the previous frame"; null = 0) must have colour's size.
/// NaN/Inf read as 0, negative colours as 0.
struct UpscaleInput {
  const FloatImage* color = nullptr;
  const FloatImage* depth = nullptr;
  const FloatImage* motion = nullptr;
  float jitter_x = 0.5f, jitter_y = 0.5f;
};

struct UpscalerOptions {
  UpscaleMethod method = UpscaleMethod::neural;
  int factor = 2;       ///< 2 or 4: the output is factor x the input in each dimension
  std::string weights;  ///< neural, nsrr, nsrr-rt: weights ("" = default_upscaler_weights(method))
  /// neural, nsrr, nsrr-rt: bf16 convolutions where the CPU has them (AVX-512 BF16; else fp32)
  bool bf16 = true;
};

/// $KESTREL_WEIGHTS_DIR/upscaler.kdw (upscaler_nsrr.kdw for nsrr, upscaler_nsrr_rt.kdw for
/// nsrr-rt), else the source tree's weights/ file of that name.
std::string default_upscaler_weights(UpscaleMethod method = UpscaleMethod::neural);

/// An upsampler for one sequence (the history carries from frame to frame; reset() starts a
/// new sequence, as does a change of input size). Work runs on the caller's TBB arena.
class Upscaler {
 public:
  /// Throws Error for a factor other than 2 or 4, or naming the file for a missing, corrupt
  /// or mismatched weights file.
  explicit Upscaler(const UpscalerOptions& options = {});
  ~Upscaler();
  Upscaler(Upscaler&&) noexcept;
  Upscaler& operator=(Upscaler&&) noexcept;

  /// Upsamples one frame to factor x its size (3 channels, linear). Throws Error on missing
  /// colour, mismatched sizes or channel counts, or a non-finite jitter.
  FloatImage upscale(const UpscaleInput& input);
  /// The same into `out`, reusing its storage.
  void upscale(const UpscaleInput& input, FloatImage& out);
  void reset();
  UpscaleMethod method() const;
  int factor() const;
  size_t parameter_count() const;  ///< 0 for the baselines
  bool uses_bf16() const;          ///< the network running its convolutions in bf16
  /// Milliseconds of the last frame's stages: features, network, reconstruction, and for nsrr
  /// and nsrr-rt the learned TAAU run beside them (its whole frame: history).
  struct Times {
    double features = 0, network = 0, reconstruct = 0, history = 0;
  };
  Times last_times() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace kestrel
