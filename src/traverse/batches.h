// Splitting a batch of rays into the runs the kernels may see. Not included by the per-ISA
// kernel files (its inline functions must be compiled for the baseline ISA only).
#pragma once
#include <cstddef>
#include <span>

#include "geometry/triangle_intersect.h"

namespace kestrel::kernels {

/// Calls fn(rays, out, n) on each run of traceable rays (finite, non-zero direction,
/// tmin <= tmax) and writes a default Out (a miss) for every other ray: for the ray-stream
/// kernels, which only ever see rays that can hit (the others test each ray as they load it:
/// a separate pass over a batch read its rays from memory twice).
template <class Out, class Fn>
void for_each_traceable_run(std::span<const Ray> rays, Out* out, Fn&& fn) {
  size_t i = 0;
  const size_t n = rays.size();
  while (i < n) {
    size_t j = i;
    while (j < n && is_traceable(rays[j])) ++j;
    if (j > i) fn(rays.data() + i, out + i, j - i);
    if (j < n) out[j] = Out{};
    i = j + 1;
  }
}

}  // namespace kestrel::kernels
