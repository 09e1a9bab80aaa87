// The `nsrr` upsampler (Xiao et al. 2020): features of the current and the N = 3 previous
// frames, zero-upsampled, backward-warped by the accumulated motion, reweighted, and a U-Net
// reconstruction at the output resolution. scripts/upscale/nsrr.py is the reference
// definition; the convolutions run through oneDNN (bf16 where the CPU has it).
#pragma once
#include <memory>
#include <string>

#include "kestrel/image.h"
#include "kestrel/upscale.h"

namespace kestrel::upscale {

class Nsrr {
 public:
  /// Throws Error naming the file for a missing, corrupt or mismatched weights file.
  Nsrr(const std::string& weights, int factor, bool bf16);
  ~Nsrr();
  Nsrr(Nsrr&&) noexcept;
  Nsrr& operator=(Nsrr&&) noexcept;

  /// One frame (the input already checked by the Upscaler): out becomes factor x its size.
  /// times: features (extraction, zero-upsampling, warping), networks, output.
  void run(const UpscaleInput& in, FloatImage& out, Upscaler::Times& times);
  void reset();
  size_t parameters() const;
  bool bf16() const;  ///< whether the convolutions run in bf16

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace kestrel::upscale
