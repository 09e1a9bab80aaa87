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
// Builder rows fitted from the amortization benchmark of 2026-12-04 (AMD Zen 5, after the
// build-buffer pool and the direct wide LBVH; scenes bunny_grid, lamborghini, sponza, teapot;
// docs/amortization.csv). ray_ns_base and ray_ns_per_log2n are the 2026-12-03 fit's: this
// run's line through the four scenes had a negative intercept (-42.4 ns, 8.99 per log2 n),
// which would predict negative trace times for scenes of a few dozen triangles.
constexpr double ray_ns_base = 21.93, ray_ns_per_log2n = 5.49;
constexpr BuilderCost costs[] = {
    {Builder::median, 396.6, 1.206},   {Builder::lbvh, 123.8, 1.154},
    {Builder::binned, 557.2, 1.000},   {Builder::sweep, 1155.1, 1.003},
    {Builder::spatial, 2245.1, 0.948},
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
