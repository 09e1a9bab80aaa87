// kestrel public API: the float image every stage passes on (AOVs, denoiser and upsampler
// inputs and outputs), on its own so those stages' headers need nothing of the BVH.
#pragma once
#include <cstddef>
#include <vector>

namespace kestrel {

/// A float image: rows top to bottom, `channels` interleaved floats per pixel.
struct FloatImage {
  int width = 0, height = 0, channels = 0;
  std::vector<float> pixels;
  FloatImage() = default;
  FloatImage(int w, int h, int c)
      : width(w), height(h), channels(c), pixels(size_t(w) * size_t(h) * size_t(c), 0.0f) {}
  /// w x h x c, keeping the storage when it is large enough (the values are left as they
  /// are: for a caller that writes every pixel).
  void reshape(int w, int h, int c) {
    width = w, height = h, channels = c;
    pixels.resize(size_t(w) * size_t(h) * size_t(c));
  }
  float* at(int x, int y) {
    return &pixels[(size_t(y) * size_t(width) + size_t(x)) * size_t(channels)];
  }
  const float* at(int x, int y) const {
    return &pixels[(size_t(y) * size_t(width) + size_t(x)) * size_t(channels)];
  }
};

}  // namespace kestrel
