// Random numbers and sample warping for the renderer: a counter-seeded PCG32 per path
// sample (so images do not depend on threads or tiling), the Halton jitter, and piecewise
// constant distributions for light and environment sampling.
#pragma once
#include <algorithm>
#include <cstdint>
#include <span>
#include <vector>

namespace kestrel::render {

/// The splitmix64 finaliser, of a uint64_t or of a vector of them (the SIMD lanes of
/// render/surface_rows.inl do the same operations).
template <class U>
inline U mix64(U x) {
  x ^= x >> 30;
  x *= uint64_t(0xBF58476D1CE4E5B9ull);
  x ^= x >> 27;
  x *= uint64_t(0x94D049BB133111EBull);
  x ^= x >> 31;
  return x;
}

/// PCG32's multiplier (each step: state * pcg_multiplier + increment).
inline constexpr uint64_t pcg_multiplier = 6364136223846793005ull;

/// A generator's state and increment for (seed, frame, pixel, sample), before its first step;
/// `pixel` a uint64_t or a vector of them (render/surface_rows.inl).
template <class U>
inline void pcg_seed(uint64_t seed, uint64_t frame, U pixel, uint64_t sample, U& state, U& inc) {
  state =
      mix64(seed ^ mix64(frame * uint64_t(0x9E3779B97F4A7C15ull) ^ mix64(pixel + (sample << 32))));
  inc = (mix64(state + sample) << 1) | uint64_t(1);
}

/// PCG32 (O'Neill 2014, XSH-RR), seeded from (seed, frame, pixel, sample).
class Rng {
 public:
  Rng(uint64_t seed, uint64_t frame, uint64_t pixel, uint64_t sample) {
    pcg_seed(seed, frame, pixel, sample, state_, inc_);
    next();
  }
  uint32_t next() {
    const uint64_t old = state_;
    state_ = old * pcg_multiplier + inc_;
    const uint32_t xorshifted = uint32_t(((old >> 18u) ^ old) >> 27u);
    const uint32_t rot = uint32_t(old >> 59u);
    return (xorshifted >> rot) | (xorshifted << ((32u - rot) & 31u));
  }
  /// Uniform in [0, 1).
  float uniform() { return float(next() >> 8) * 0x1p-24f; }
  uint64_t state() const { return state_; }
  uint64_t increment() const { return inc_; }
  /// Continues from `state` (render::PathDraws': the state after draws made ahead).
  void set_state(uint64_t state) { state_ = state; }
  /// The generator of this state and increment (render::CameraRowsArgs' output).
  static Rng from_state(uint64_t state, uint64_t inc) {
    Rng g;
    g.state_ = state, g.inc_ = inc;
    return g;
  }

 private:
  Rng() = default;
  uint64_t state_, inc_;
};

inline float radical_inverse(uint32_t base, uint32_t index) {
  float inv = 1.0f / float(base), f = inv, r = 0;
  while (index > 0) {
    r += f * float(index % base);
    index /= base;
    f *= inv;
  }
  return r;
}

/// A discrete distribution over weights (>= 0), sampled by inverting its CDF.
class Distribution1D {
 public:
  Distribution1D() = default;
  explicit Distribution1D(std::span<const float> weights) {
    cdf_.resize(weights.size() + 1);
    cdf_[0] = 0;
    double sum = 0;
    for (size_t i = 0; i < weights.size(); ++i) {
      sum += std::max(0.0f, weights[i]);
      cdf_[i + 1] = float(sum);
    }
    total_ = float(sum);
    if (sum > 0)
      for (float& c : cdf_) c = float(c / sum);
  }
  size_t size() const { return cdf_.empty() ? 0 : cdf_.size() - 1; }
  float total() const { return total_; }
  float pmf(size_t i) const { return cdf_[i + 1] - cdf_[i]; }
  /// Index for u in [0, 1) and the remapped u in [0, 1) within the chosen cell.
  size_t sample(float u, float* remapped = nullptr) const {
    const size_t n = size();
    size_t i = size_t(std::upper_bound(cdf_.begin() + 1, cdf_.end(), u) - cdf_.begin()) - 1;
    i = std::min(i, n - 1);
    while (pmf(i) <= 0 && i + 1 < n) ++i;  // u landed exactly on a zero-width cell
    while (pmf(i) <= 0 && i > 0) --i;
    if (remapped)
      *remapped = std::clamp((u - cdf_[i]) / std::max(pmf(i), 1e-30f), 0.0f, 0x1.fffffep-1f);
    return i;
  }

 private:
  std::vector<float> cdf_;
  float total_ = 0;
};

}  // namespace kestrel::render
