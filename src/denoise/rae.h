// The `rae` denoiser: the recurrent denoising autoencoder of Chaitanya et al. 2017, the
// quality mode the fast neural denoiser is measured against. scripts/denoise/rae.py is the
// reference definition; this runs the same function through oneDNN (tests/denoise compares
// the two on a fixture). Seconds per 720p frame on two threads: for final frames.
#pragma once
#include <cstddef>
#include <memory>
#include <string>

#include "denoise/neural.h"

namespace kestrel::denoise {

class Rae {
 public:
  /// Throws Error naming the file for a missing, corrupt or foreign weights file. `bf16`:
  /// bf16 activations and weights in the convolutions where the CPU has them (oneDNN's
  /// avx512_core_bf16 or better), accumulation in f32; else fp32.
  Rae(const std::string& weights, bool bf16);
  ~Rae();
  Rae(Rae&&) noexcept;
  Rae& operator=(Rae&&) noexcept;

  size_t parameters() const;
  bool bf16() const;  ///< whether the convolutions run in bf16
  /// The next frame starts a new sequence (recurrent states at 0).
  void reset();
  /// One frame: `in` the gathered inputs (13 planes, no padding: colour, albedo, normal,
  /// depth, roughness, motion), `out` 3 planes of the same size. A size change restarts the
  /// sequence.
  void run(const Planes& in, Planes& out);

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace kestrel::denoise
