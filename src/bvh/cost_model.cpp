// The cost model behind BuildQuality::automatic (see predicted_seconds in kestrel/bvh.h).
// Constants: scripts/fit_cost_model.py on the amortization CSV of kestrel_trace_bench
// (one thread, 640x360 primary + diffuse rays per scene; scenes under 1000 triangles are
// left out of the fit; the run is docs/amortization.csv, described in docs/benchmarks.md).
// Refit when builders or kernels change.
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
// fitted from a first run of the amortization benchmark (2026-12-03, AMD EPYC, the CSV in
// docs/ is a second run): scenes bunny_grid, lamborghini, sponza, teapot
constexpr double ray_ns_base = 21.93, ray_ns_per_log2n = 5.49;
constexpr BuilderCost costs[] = {
    {Builder::median, 397.4, 1.247},   {Builder::lbvh, 185.5, 1.080},
    {Builder::binned, 549.3, 1.000},   {Builder::sweep, 1012.0, 0.987},
    {Builder::spatial, 2210.3, 0.941},
};
}  // namespace

double predicted_seconds(Builder builder, size_t prim_count, double rays) {
  const double n = double(prim_count);
  const double ray_ns = ray_ns_base + ray_ns_per_log2n * std::log2(std::max(2.0, n));
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
