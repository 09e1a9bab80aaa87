// The cost model behind BuildQuality::automatic (internal: tests and the amortization
// benchmark read it; users pick a quality).
#pragma once
#include <cstddef>

#include "kestrel/bvh.h"

namespace kestrel {

/// The cost model of BuildQuality::automatic: predicted seconds, one thread, to build over
/// prim_count primitives with `builder` (build_accel, wide layout included) and then trace
/// `rays` rays: n * build_ns[b] + rays * (a + c * log2 n) * ray_factor[b], constants fitted
/// to the amortization benchmark (scripts/fit_cost_model.py, docs/benchmarks.md).
double predicted_seconds(Builder builder, size_t prim_count, double rays);
/// The builder (median, lbvh, binned, sweep or spatial) with the least predicted_seconds.
Builder choose_builder(size_t prim_count, double rays);
}  // namespace kestrel
