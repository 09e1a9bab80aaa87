// Scene -> Accel: validation, prim refs, the BVH, and triangles copied into leaf order.
#include <fmt/format.h>

#include "core/parallel.h"
#include "core/timer.h"
#include "geometry/prim_ref.h"
#include "kestrel/error.h"
#include "traverse/traverse_bvh2.h"

namespace kestrel {

Accel build_accel(const Scene& scene, const BuildConfig& config) {
  Timer timer;
  SceneValidation validation;
  Buffer<PrimRef> refs = validate_and_make_prim_refs(scene, validation);
  Bvh2 bvh = build_bvh(refs, config);
  // LBVH depth is bounded by its key bits (at most 3 x 21 + 32 levels) and the median split
  // by log2(n); the SAH-driven trees are checked.
  const Builder builder = resolve_builder(config);
  const bool bounded_depth = builder == Builder::lbvh || builder == Builder::median;
  if (!bounded_depth && max_depth(bvh) > max_traversal_depth) {
    // Pathological primitive distributions can make SAH trees very deep; the median split
    // bounds the depth by log2(n).
    BuildConfig fallback = config;
    fallback.builder = Builder::median;
    bvh = build_bvh(refs, fallback);
  }
  Accel accel;
  accel.triangles = gather_triangles(scene, bvh.prim_ids);
  accel.bvh = std::move(bvh);
  accel.validation = std::move(validation);
  accel.build_ms = timer.ms();
  return accel;
}

}  // namespace kestrel
