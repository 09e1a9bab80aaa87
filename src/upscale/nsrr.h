// The nsrr family of upsamplers: `nsrr` (Xiao et al. 2020: features of the current and the
// N = 3 previous frames, zero-upsampled, backward-warped by the accumulated motion, reweighted,
// and a U-Net reconstruction at the output resolution) and `nsrr-rt`, its real-time member
// (N = 2, networks on cells of 4 x 4 output pixels). Both blend the aligned samples with the
// output of the learned TAAU run beside them: the long history the window lacks.
// scripts/upscale/nsrr.py is the reference definition; the convolutions run through oneDNN (bf16
// where the CPU has it).
#pragma once
#include <memory>
#include <string>

#include "kestrel/image.h"
#include "kestrel/upscale.h"

namespace kestrel::upscale {

class NsrrNetwork {
 public:
  virtual ~NsrrNetwork() = default;
  /// One frame (the input already checked by the Upscaler): out becomes factor x its size.
  /// history: the learned TAAU's output for this frame (factor x the input's size), the
  /// blend's history candidate. times: features (clean-up, zero-upsampling, warping), networks,
  /// output.
  virtual void run(const UpscaleInput& in, const FloatImage& history, FloatImage& out,
                   Upscaler::Times& times) = 0;
  virtual void reset() = 0;
  virtual size_t parameters() const = 0;
  virtual bool bf16() const = 0;  ///< whether the convolutions run in bf16
};

/// Throw Error naming the file for a missing, corrupt or mismatched weights file.
std::unique_ptr<NsrrNetwork> make_nsrr(const std::string& weights, int factor, bool bf16);
std::unique_ptr<NsrrNetwork> make_nsrr_rt(const std::string& weights, int factor, bool bf16);

}  // namespace kestrel::upscale
