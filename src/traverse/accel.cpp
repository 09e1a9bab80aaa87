// Scene -> Accel: validation, prim refs, the BVH, then either triangles copied into leaf
// order (bvh2) or the collapse to a wide layout; refit of an existing Accel.
#include <fmt/format.h>

#include <cstring>

#include "core/parallel.h"
#include "core/timer.h"
#include "geometry/prim_ref.h"
#include "kestrel/error.h"
#include "traverse/traverse_bvh2.h"
#include "traverse/wide_bvh.h"

namespace kestrel {

std::optional<Layout> layout_from_name(const std::string& name) {
  if (name == "auto" || name == "automatic") return Layout::automatic;
  if (name == "bvh2") return Layout::bvh2;
  if (name == "bvh4") return Layout::bvh4;
  if (name == "bvh8") return Layout::bvh8;
  return std::nullopt;
}

const char* layout_name(Layout layout) {
  switch (layout) {
    case Layout::automatic: return "auto";
    case Layout::bvh2: return "bvh2";
    case Layout::bvh4: return "bvh4";
    case Layout::bvh8: return "bvh8";
  }
  return "?";
}

/// The layout `automatic` stands for on this machine: 8-wide nodes where 256-bit vectors
/// exist, else 4-wide (see docs/benchmarks.md for the measurements behind it).
Layout resolve_layout(Layout layout) {
  if (layout != Layout::automatic) return layout;
  return default_isa() == Isa::sse2 ? Layout::bvh4 : Layout::bvh8;
}

size_t Accel::memory_bytes() const {
  switch (layout) {
    case Layout::bvh4: return bvh4.nodes.size() * sizeof(Bvh4Node) + bvh4.blocks.size() * sizeof(TriangleBlock);
    case Layout::bvh8: return bvh8.nodes.size() * sizeof(Bvh8Node) + bvh8.blocks.size() * sizeof(TriangleBlock);
    default:
      return bvh.nodes.size() * sizeof(Bvh2Node) + bvh.prim_ids.size() * sizeof(uint32_t) +
             triangles.size() * sizeof(Triangle);
  }
}

Accel build_accel(const Scene& scene, const BuildConfig& config) {
  Timer timer;
  Accel accel;
  accel.layout = resolve_layout(config.layout);
  SceneValidation validation;
  Buffer<PrimRef> refs = validate_and_make_prim_refs(scene, validation);
  Bvh2 bvh = build_bvh(refs, config);
  // LBVH depth is bounded by its key bits (at most 3 x 21 + 32 levels) and the median split
  // by log2(n); the SAH-driven trees are checked.
  const Builder builder = resolve_builder(config, refs.size());
  const bool bounded_depth = builder == Builder::lbvh || builder == Builder::median;
  if (!bounded_depth && max_depth(bvh) > max_traversal_depth) {
    // Pathological primitive distributions can make SAH trees very deep; the median split
    // bounds the depth by log2(n).
    BuildConfig fallback = config;
    fallback.builder = Builder::median;
    bvh = build_bvh(refs, fallback);
  }
  accel.prim_count = bvh.prim_ids.size();
  if (!bvh.empty()) accel.bounds = {bvh.nodes[0].lo, bvh.nodes[0].hi};
  Buffer<Triangle> triangles = gather_triangles(scene, bvh.prim_ids);
  switch (accel.layout) {
    case Layout::bvh4: accel.bvh4 = collapse_to_bvh4(bvh, triangles, config.max_leaf_size); break;
    case Layout::bvh8: accel.bvh8 = collapse_to_bvh8(bvh, triangles, config.max_leaf_size); break;
    default:
      accel.triangles = std::move(triangles);
      accel.bvh = std::move(bvh);
  }
  accel.validation = std::move(validation);
  accel.build_ms = timer.ms();
  return accel;
}

void refit_accel(Accel& accel, const Scene& scene) {
  SceneValidation now = validate_scene(scene);
  if (now.valid.size() != accel.validation.valid.size())
    throw Error(ErrorCode::invalid_argument,
                fmt::format("refit: the scene has {} triangles, the accel was built over {}; rebuild",
                            now.valid.size(), accel.validation.valid.size()));
  for (size_t i = 0; i < now.valid.size(); ++i)
    if (accel.validation.valid[i] && !now.valid[i])
      throw Error(ErrorCode::invalid_argument,
                  fmt::format("refit: triangle {} is no longer valid (NaN/Inf, bad index or degenerate); rebuild", i));
  const Buffer<Triangle> global = gather_triangles(scene, now);
  Bounds3 box;
  switch (accel.layout) {
    case Layout::bvh4: refit_wide(accel.bvh4, global); break;
    case Layout::bvh8: refit_wide(accel.bvh8, global); break;
    default:
      for (size_t i = 0; i < accel.triangles.size(); ++i) accel.triangles[i] = global[accel.bvh.prim_ids[i]];
      refit_bvh2(accel.bvh, accel.triangles);
  }
  // Scene bounds from the refitted root.
  auto grow = [&](float lx, float ly, float lz, float hx, float hy, float hz) {
    box.lo = {std::min(box.lo.x, lx), std::min(box.lo.y, ly), std::min(box.lo.z, lz)};
    box.hi = {std::max(box.hi.x, hx), std::max(box.hi.y, hy), std::max(box.hi.z, hz)};
  };
  if (accel.layout == Layout::bvh4 && !accel.bvh4.empty()) {
    const Bvh4Node& r = accel.bvh4.nodes[0];
    for (int j = 0; j < 4; ++j)
      if (r.child[j] != wide_empty) grow(r.bounds[0][j], r.bounds[2][j], r.bounds[4][j], r.bounds[1][j], r.bounds[3][j], r.bounds[5][j]);
  } else if (accel.layout == Layout::bvh8 && !accel.bvh8.empty()) {
    const Bvh8Node& r = accel.bvh8.nodes[0];
    for (int j = 0; j < 8; ++j)
      if (r.child[j] != wide_empty) grow(r.bounds[0][j], r.bounds[2][j], r.bounds[4][j], r.bounds[1][j], r.bounds[3][j], r.bounds[5][j]);
  } else if (!accel.bvh.empty()) {
    box = {accel.bvh.nodes[0].lo, accel.bvh.nodes[0].hi};
  }
  accel.bounds = box;
}

}  // namespace kestrel
