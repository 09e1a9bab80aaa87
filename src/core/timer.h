// Wall-clock timing for benchmarks and build statistics.
#pragma once
#include <chrono>
#include <vector>

namespace kestrel {

/// Milliseconds since construction (steady clock).
class Timer {
 public:
  Timer() : start_(std::chrono::steady_clock::now()) {}
  double ms() const {
    return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start_)
        .count();
  }

 private:
  std::chrono::steady_clock::time_point start_;
};

/// Median of the samples (mean of the middle two for even counts); 0 for none.
double median(std::vector<double> samples);

}  // namespace kestrel
