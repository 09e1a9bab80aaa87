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
// Fitted from the amortization benchmark of 2026-12-05 (evening; AMD Zen 5, after the builds'
// denormal, validation and collapse work; scenes bunny_grid, lamborghini, sponza, teapot; the
// first of two runs, the second judged it: docs/amortization.csv). The per-ray line through
// the four scenes has a negative intercept (it is a line through four points, not a law):
// floored at ray_ns_min, it stays positive for the smallest scenes.
constexpr double ray_ns_base = -23.47, ray_ns_per_log2n = 6.91, ray_ns_min = 10.0;
constexpr BuilderCost costs[] = {
    {Builder::median, 352.9, 1.243},   {Builder::lbvh, 74.3, 1.146},
    {Builder::binned, 282.9, 1.000},   {Builder::sweep, 905.5, 1.004},
    {Builder::spatial, 1708.7, 0.963},
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
