// Scene -> Accel: validation, prim refs, the BVH, then either triangles copied into leaf
// order (bvh2) or the collapse to a wide layout; refit of an existing Accel.
#include <fmt/format.h>

#include <algorithm>
#include <cstring>

#include "core/parallel.h"
#include "core/timer.h"
#include "core/vec.h"
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
    case Layout::automatic:
      return "auto";
    case Layout::bvh2:
      return "bvh2";
    case Layout::bvh4:
      return "bvh4";
    case Layout::bvh8:
      return "bvh8";
  }
  return "?";
}

/// The layout `automatic` stands for on this machine: 8-wide nodes where 256-bit vectors
/// exist, else 4-wide (see docs/benchmarks.md for the measurements behind it).
Layout resolve_layout(Layout layout) {
  if (layout != Layout::automatic) return layout;
  return default_isa() == Isa::sse2 ? Layout::bvh4 : Layout::bvh8;
}

Accel::Accel() : nodes(std::make_unique<detail::AccelNodes>()) {}
Accel::~Accel() = default;
Accel::Accel(Accel&&) noexcept = default;
Accel& Accel::operator=(Accel&&) noexcept = default;

size_t Accel::memory_bytes() const {
  const detail::AccelNodes& n = *nodes;
  switch (layout) {
    case Layout::bvh4:
      return n.bvh4.nodes.size() * sizeof(Bvh4Node) + n.bvh4.blocks.size() * sizeof(TriangleBlock);
    case Layout::bvh8:
      return n.bvh8.nodes.size() * sizeof(Bvh8Node) + n.bvh8.blocks.size() * sizeof(TriangleBlock);
    default:
      return n.bvh.nodes.size() * sizeof(Bvh2Node) + n.bvh.prim_ids.size() * sizeof(uint32_t) +
             n.triangles.size() * sizeof(Triangle);
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
  accel.builder = builder;
  const bool bounded_depth = builder == Builder::lbvh || builder == Builder::median;
  if (!bounded_depth && max_depth(bvh) > max_traversal_depth) {
    // Pathological primitive distributions can make SAH trees very deep; the median split
    // bounds the depth by log2(n). Reported in the Accel, not silent.
    BuildConfig fallback = config;
    fallback.builder = Builder::median;
    bvh = build_bvh(refs, fallback);
    accel.builder = Builder::median;
    accel.depth_fallback = true;
  }
  accel.prim_count = bvh.prim_ids.size();
  if (!bvh.empty()) accel.bounds = {bvh.nodes[0].lo, bvh.nodes[0].hi};
  Buffer<Triangle> triangles = gather_triangles(scene, bvh.prim_ids);
  switch (accel.layout) {
    case Layout::bvh4:
      accel.nodes->bvh4 = collapse_to_bvh4(bvh, triangles, config.max_leaf_size);
      break;
    case Layout::bvh8:
      accel.nodes->bvh8 = collapse_to_bvh8(bvh, triangles, config.max_leaf_size);
      break;
    default:
      accel.nodes->triangles = std::move(triangles);
      accel.nodes->bvh = std::move(bvh);
  }
  accel.validation = std::move(validation);
  accel.build_ms = timer.ms();
  return accel;
}

namespace {
// Wide layouts: every block lane is re-read from its mesh by prim id (it must still have
// finite vertices and valid indices); the boxes are recomputed in the same pass.
class BlockRewriter {
 public:
  explicit BlockRewriter(const Scene& scene) : scene_(scene), one_mesh_(scene.meshes.size() == 1) {
    size_t offset = 0;
    for (const TriangleMesh& mesh : scene.meshes) {
      first_.push_back(offset);
      offset += mesh.triangle_count();
    }
  }
  void operator()(TriangleBlock& blk) const {
    for (int lane = 0; lane < 4; ++lane) {
      const uint32_t id = blk.prim_id[lane] & ~block_last_bit;
      if (lane > 0 &&
          id == (blk.prim_id[lane - 1] & ~block_last_bit)) {  // padding: repeat the lane
        for (int k = 0; k < 3; ++k)
          for (int a = 0; a < 3; ++a) blk.v[k][a][lane] = blk.v[k][a][lane - 1];
        continue;
      }
      const size_t m = one_mesh_
                           ? 0
                           : size_t(std::upper_bound(first_.begin(), first_.end(), size_t(id)) -
                                    first_.begin()) -
                                 1;
      const TriangleMesh& mesh = scene_.meshes[m];
      const size_t t = id - first_[m];
      // A triangle that became NaN/Inf or lost a vertex cannot stay; one that became
      // degenerate can (no ray hits it), so only finiteness and indices are checked.
      const uint32_t* idx = &mesh.indices[3 * t];
      const size_t nv = mesh.positions.size();
      if (idx[0] >= nv || idx[1] >= nv || idx[2] >= nv || !is_finite(mesh.positions[idx[0]]) ||
          !is_finite(mesh.positions[idx[1]]) || !is_finite(mesh.positions[idx[2]]))
        throw Error(
            ErrorCode::invalid_argument,
            fmt::format(
                "refit: triangle {} is no longer valid (NaN/Inf vertex or bad index); rebuild",
                id));
      write_block_lane(blk, lane,
                       {mesh.positions[idx[0]], mesh.positions[idx[1]], mesh.positions[idx[2]]});
    }
  }

 private:
  const Scene& scene_;
  bool one_mesh_;
  std::vector<size_t> first_;
};
}  // namespace

void refit_accel(Accel& accel, const Scene& scene) {
  const size_t count = scene.triangle_count();
  if (count != accel.validation.valid.size())
    throw Error(
        ErrorCode::invalid_argument,
        fmt::format("refit: the scene has {} triangles, the accel was built over {}; rebuild",
                    count, accel.validation.valid.size()));
  Bounds3 box;
  switch (accel.layout) {
    case Layout::bvh4:
      refit_wide(accel.nodes->bvh4, BlockRewriter(scene));
      break;
    case Layout::bvh8:
      refit_wide(accel.nodes->bvh8, BlockRewriter(scene));
      break;
    default: {
      SceneValidation now = validate_scene(scene);
      for (size_t i = 0; i < now.valid.size(); ++i)
        if (accel.validation.valid[i] && !now.valid[i])
          throw Error(ErrorCode::invalid_argument,
                      fmt::format("refit: triangle {} is no longer valid (NaN/Inf, bad index or "
                                  "degenerate); rebuild",
                                  i));
      const Buffer<Triangle> global = gather_triangles(scene, now);
      for (size_t i = 0; i < accel.nodes->triangles.size(); ++i)
        accel.nodes->triangles[i] = global[accel.nodes->bvh.prim_ids[i]];
      refit_bvh2(accel.nodes->bvh, accel.nodes->triangles);
    }
  }
  // Scene bounds from the refitted root.
  if (accel.layout == Layout::bvh4) {
    box = wide_bounds(accel.nodes->bvh4);
  } else if (accel.layout == Layout::bvh8) {
    box = wide_bounds(accel.nodes->bvh8);
  } else if (!accel.nodes->bvh.empty()) {
    box = {accel.nodes->bvh.nodes[0].lo, accel.nodes->bvh.nodes[0].hi};
  }
  accel.bounds = box;
}

}  // namespace kestrel
