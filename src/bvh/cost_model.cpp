// The cost model behind BuildQuality::automatic (see predicted_seconds in kestrel/bvh.h).
// Constants: scripts/fit_cost_model.py on the amortization CSV of kestrel_trace_bench
// (one thread, 640x360 primary + diffuse rays per scene; scenes under 1000 triangles are
// left out of the fit; the run is docs/amortization.csv, described in docs/benchmarks.md).
// Refit when builders or kernels change.
#include <algorithm>
#include <cmath>

#include "bvh/cost_model.h"
#include "kestrel/bvh.h"

namespace kestrel {

namespace {
struct BuilderCost {
  Builder builder;
  double build_ns_per_prim;  // build_accel, wide layout included
  double ray_factor;         // trace cost per ray relative to binned
};
// Fitted from the amortization benchmark of 2026-12-05 (night; AMD Zen 5, after the collapse
// took each wide node's slots by the SAH-optimal program, which made the binned, sweep, median
// and spatial trees faster to trace and the LBVH's relatively slower; scenes bunny_grid,
// lamborghini, sponza, teapot; the first of two runs, the second judged it:
// docs/amortization.csv). The per-ray line is one through four points, not a law: floored at
// ray_ns_min for the smallest scenes.
constexpr double ray_ns_base = 22.42, ray_ns_per_log2n = 4.11, ray_ns_min = 10.0;
constexpr BuilderCost costs[] = {
    {Builder::median, 373.9, 1.415},   {Builder::lbvh, 86.7, 1.262},
    {Builder::binned, 342.6, 1.000},   {Builder::sweep, 1077.5, 1.015},
    {Builder::spatial, 2074.0, 0.954},
};
}  // namespace

double predicted_seconds(Builder builder, size_t prim_count, double rays) {
  const double n = double(prim_count);
  const double ray_ns =
      std::max(ray_ns_min, ray_ns_base + ray_ns_per_log2n * std::log2(std::max(2.0, n)));
  for (const BuilderCost& c : costs)
    if (c.builder == builder)
      return (n * c.build_ns_per_prim + rays * ray_ns * c.ray_factor) * 1e-9;
  return INFINITY;  // treelet: not in the model (patented, never chosen automatically)
}

Builder choose_builder(size_t prim_count, double rays) {
  Builder best = Builder::binned;
  double best_s = INFINITY;
  for (const BuilderCost& c : costs) {
    const double s = predicted_seconds(c.builder, prim_count, rays);
    if (s < best_s) {
      best_s = s;
      best = c.builder;
    }
  }
  return best;
}

}  // namespace kestrel
