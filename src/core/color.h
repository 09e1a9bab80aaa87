// Colour encodings shared by the image readers, the texture sampler and the loaders.
#pragma once
#include <cmath>

namespace kestrel {

/// The sRGB transfer function's inverse: an encoded value in [0, 1] to linear.
inline float srgb_to_linear(float c) {
  return c <= 0.04045f ? c / 12.92f : std::pow((c + 0.055f) / 1.055f, 2.4f);
}

}  // namespace kestrel
