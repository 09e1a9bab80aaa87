// Networks run through oneDNN (Debian's libdnnl): a chain of primitives built once per input
// size, and the layers kestrel's oneDNN networks are made of (the nsrr upsamplers, the rae
// denoiser). Included only by the files that build such networks (oneDNN's header is heavy).
#pragma once
#include <oneapi/dnnl/dnnl.hpp>
#include <unordered_map>
#include <vector>

#include "nn/weights.h"

namespace kestrel::nn {

/// A chain of oneDNN primitives and the memories they read and write.
struct Net {
  struct Step {
    dnnl::primitive p;
    std::unordered_map<int, dnnl::memory> args;
  };
  std::vector<Step> steps;
  void run(dnnl::stream& s) {
    for (Step& st : steps) st.p.execute(s, st.args);
  }
};

/// The networks' building blocks on one engine, f32 or bf16 activations.
struct Dnn {
  dnnl::engine eng{dnnl::engine::kind::cpu, 0};
  dnnl::stream strm{eng};
  bool bf16 = false;

  static bool bf16_available();
  dnnl::memory::data_type act() const {
    return bf16 ? dnnl::memory::data_type::bf16 : dnnl::memory::data_type::f32;
  }
  /// A convolution of `L` (its kernel size, padding to keep the size) on `in` (batch x L.cin x
  /// hh x ww), ReLU after it if `relu` (leaky with slope `slope`), `extra` post-ops before;
  /// `last`: f32 output in the layout `last_tag`.
  dnnl::memory conv(Net& net, dnnl::memory in, const ConvLayer& L, bool relu, bool last,
                    const dnnl::post_ops* extra = nullptr,
                    dnnl::memory::format_tag last_tag = dnnl::memory::format_tag::nchw,
                    float slope = 0.0f);
  dnnl::memory pool(Net& net, dnnl::memory in);  ///< 2x2 max pooling
  /// 2x upsampling of `low` (bilinear, edges clamped; or nearest) concatenated with `skip` by
  /// channel.
  dnnl::memory up_concat(Net& net, dnnl::memory low, dnnl::memory skip, bool nearest = false);
  /// `a` and `b` concatenated by channel.
  dnnl::memory concat(Net& net, dnnl::memory a, dnnl::memory b);
  /// A step copying `from` into `to` (any layouts of the same dimensions).
  void copy(Net& net, dnnl::memory from, dnnl::memory to);

 private:
  dnnl::memory weights_of(const ConvLayer& L, const dnnl::memory::desc& want);
};

}  // namespace kestrel::nn
