// Denoising path-traced frames: kestrel's recurrent neural denoiser (a small CNN at 1/4
// resolution predicting the per-pixel temporal blend and edge-stopping strengths of a
// full-resolution a-trous filter on albedo-demodulated colour), a quality mode (the
// recurrent denoising autoencoder of Chaitanya et al. 2017, oneDNN) and two non-neural
// baselines, an edge-avoiding a-trous wavelet filter (Dammertz et al. 2010) and an
// SVGF-like filter (Schied et al. 2017). See docs/denoiser.md.
#pragma once
#include <memory>
#include <optional>
#include <string>
#include <string_view>

#include "kestrel/image.h"

namespace kestrel {

enum class DenoiseMethod { neural, svgf, atrous, rae };
const char* denoise_method_name(DenoiseMethod m);
std::optional<DenoiseMethod> denoise_method_from_name(std::string_view name);

/// One frame's inputs (pointers, not owned). colour is required (3 channels, linear HDR);
/// the rest may be null: albedo (3; default 1), normal (3, world space; default none),
/// depth (1; default 1), roughness (1; default 0), motion (2 or 3 channels, pixels, "p +
/// motion = where the surface was in the previous frame"; default 0). Every given image must
/// have colour's size. NaN/Inf values are read as 0, negative colours as 0.
struct DenoiseInput {
  const FloatImage* color = nullptr;
  const FloatImage* albedo = nullptr;
  const FloatImage* normal = nullptr;
  const FloatImage* depth = nullptr;
  const FloatImage* roughness = nullptr;
  const FloatImage* motion = nullptr;
};

struct DenoiserOptions {
  DenoiseMethod method = DenoiseMethod::neural;
  /// neural, rae: weights file ("" = default_denoiser_weights(method))
  std::string weights;
  bool recurrent = true;  ///< neural, rae: carry the state (false: every frame starts afresh)
  bool bf16 = true;       ///< neural, rae: bf16 convolutions where the CPU has them (else fp32)
};

/// Where the committed weights are: $KESTREL_WEIGHTS_DIR/FILE, else the source tree's
/// weights/FILE; FILE denoiser.kdw (neural) or denoiser_rae.kdw (rae).
std::string default_denoiser_weights(DenoiseMethod method = DenoiseMethod::neural);

/// A denoiser for one sequence of frames (state carries from frame to frame; reset() starts
/// a new sequence). Work runs on the TBB thread pool of the caller's arena.
class Denoiser {
 public:
  /// Throws Error naming the file for a missing, corrupt or mismatched weights file.
  explicit Denoiser(const DenoiserOptions& options = {});
  ~Denoiser();
  Denoiser(Denoiser&&) noexcept;
  Denoiser& operator=(Denoiser&&) noexcept;

  /// Denoises one frame (3 channels, colour's size). Throws Error on missing colour or
  /// mismatched sizes / channel counts (naming the input).
  FloatImage denoise(const DenoiseInput& input);
  /// The same into `out`, reusing its storage (neural: no allocation per frame once warm;
  /// the SVGF-like and a-trous baselines still allocate their scratch images per frame).
  void denoise(const DenoiseInput& input, FloatImage& out);
  void reset();
  DenoiseMethod method() const;
  size_t parameter_count() const;  ///< 0 for the non-neural filters
  bool uses_bf16() const;          ///< neural / rae running its convolutions in bf16

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace kestrel
