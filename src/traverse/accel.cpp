// Scene -> Accel: validation, prim refs, the BVH, then either triangles copied into leaf
// order (bvh2) or the collapse to a wide layout; refit of an existing Accel.
#include <fmt/format.h>
#include <xmmintrin.h>

#include <algorithm>
#include <cmath>
#include <cstring>

#include "bvh/builders.h"
#include "core/parallel.h"
#include "core/timer.h"
#include "core/vec.h"
#include "geometry/prim_ref.h"
#include "kestrel/error.h"
#include "traverse/morton_wide.h"
#include "traverse/stream.h"
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

detail::AccelNodes::AccelNodes() : choices(std::make_unique<PacketChoices>()) {}
detail::AccelNodes::~AccelNodes() = default;

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
  Bounds3 centroids;  // the valid refs' centroid bounds, from the same pass (the LBVH's box)
  Buffer<PrimRef> refs = validate_and_make_prim_refs(scene, validation, &centroids);
  // Wide layouts: the build that knows its leaves become 4-triangle blocks.
  const bool blocks = accel.layout == Layout::bvh4 || accel.layout == Layout::bvh8;
  const Builder builder = resolve_builder(config, refs.size());
  if (builder == Builder::lbvh && blocks) {
    // Straight from Morton order to the wide layout (morton_wide.h): no binary tree, no
    // collapse. Its depth is bounded by the key bits, as the binary LBVH's.
    accel.builder = builder;
    accel.prim_count = refs.size();
    if (accel.layout == Layout::bvh4) {
      accel.nodes->bvh4 = build_morton_bvh4(scene, refs, config, &centroids);
      if (!accel.nodes->bvh4.empty()) accel.bounds = wide_bounds(accel.nodes->bvh4);
    } else {
      accel.nodes->bvh8 = build_morton_bvh8(scene, refs, config, &centroids);
      if (!accel.nodes->bvh8.empty()) accel.bounds = wide_bounds(accel.nodes->bvh8);
    }
    accel.validation = std::move(validation);
    accel.build_ms = timer.ms();
    return accel;
  }
  const Buffer<Triangle> by_id = triangles_for_builder(scene, validation, builder);
  Bvh2 bvh = blocks ? build_bvh_for_blocks(refs, by_id, config) : build_bvh(refs, by_id, config);
  // LBVH depth is bounded by its key bits (at most 3 x 21 + 32 levels) and the median split
  // by log2(n); the SAH-driven trees are checked.
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
  accel.prim_count = refs.size();  // spatial splits may reference a triangle from several leaves
  if (!bvh.empty()) accel.bounds = {bvh.nodes[0].lo, bvh.nodes[0].hi};
  // Wide layouts read the leaves' triangles from the meshes as they write the blocks (no
  // gathered copy), unless the builder has them by id already (spatial splits).
  Buffer<Triangle> triangles;
  if (!by_id.empty()) {
    triangles = Buffer<Triangle>(bvh.prim_ids.size());
    for (size_t i = 0; i < bvh.prim_ids.size(); ++i) triangles[i] = by_id[bvh.prim_ids[i]];
  } else if (!blocks) {
    triangles = gather_triangles(scene, bvh.prim_ids);
  }
  switch (accel.layout) {
    case Layout::bvh4:
      accel.nodes->bvh4 = by_id.empty() ? collapse_to_bvh4(bvh, scene, config.max_leaf_size)
                                        : collapse_to_bvh4(bvh, triangles, config.max_leaf_size);
      break;
    case Layout::bvh8:
      accel.nodes->bvh8 = by_id.empty() ? collapse_to_bvh8(bvh, scene, config.max_leaf_size)
                                        : collapse_to_bvh8(bvh, triangles, config.max_leaf_size);
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
// finite vertices and valid indices); the block pass then recomputes the boxes. Blocks are in
// tree order and vertices in mesh order, so each lane's index and vertex reads are gathers:
// the indices are prefetched 16 blocks ahead (measured on the Lamborghini: 1.4x faster; also
// prefetching the vertices was not), and a block's 12 vertices become its 9 coordinate rows by
// three 4x4 transposes. Padding lanes repeat a prim id, so gathering them repeats the lane as the
// layout wants.
class BlockRewriter {
 public:
  explicit BlockRewriter(const Scene& scene) : scene_(scene), starts_(scene) {}
  uint32_t operator()(std::span<TriangleBlock> blocks) const {
    if (scene_.meshes.size() == 1) {
      const TriangleMesh& mesh = scene_.meshes[0];
      return rewrite(blocks, [&](uint32_t id) { return Located{&mesh, id}; });
    }
    return rewrite(blocks, [&](uint32_t id) {  // one binary search per lane
      const size_t m = starts_.mesh_of(id);
      return Located{&scene_.meshes[m], id - starts_.start(m)};
    });
  }

 private:
  static constexpr size_t index_ahead = 16;
  struct Located {  // a global prim id's mesh and triangle index in it
    const TriangleMesh* mesh;
    size_t t;
  };

  static uint32_t lane_id(const TriangleBlock& b, int lane) {
    return b.prim_id[lane] & ~block_last_bit;
  }

  // Vertex v of a mesh as x, y, z, (junk): a 16-byte load unless it is the last vertex.
  static __m128 load_vertex(const TriangleMesh& mesh, uint32_t v) {
    const float* p = &mesh.positions[v].x;
    return v + 1 < mesh.positions.size() ? _mm_loadu_ps(p) : _mm_setr_ps(p[0], p[1], p[2], 0.0f);
  }

  template <class Locate>
  static uint32_t rewrite(std::span<TriangleBlock> blocks, const Locate& locate) {
    uint32_t bad = ~0u;
    for (size_t b = 0; b < blocks.size(); ++b) {
      if (b + index_ahead < blocks.size())
        for (int lane = 0; lane < 4; ++lane) {
          const uint32_t id = lane_id(blocks[b + index_ahead], lane);
          const Located l = locate(id);
          __builtin_prefetch(l.mesh->indices.data() + 3 * l.t);
        }
      TriangleBlock& blk = blocks[b];
      __m128 rows[3][4];  // [vertex k][lane] as x, y, z, junk
      bool indices_ok = true;
      for (int lane = 0; lane < 4; ++lane) {
        const uint32_t id = lane_id(blk, lane);
        const Located l = locate(id);
        const TriangleMesh& mesh = *l.mesh;
        const size_t t = l.t, nv = mesh.positions.size();
        const uint32_t* idx = &mesh.indices[3 * t];
        if (idx[0] >= nv || idx[1] >= nv || idx[2] >= nv) {
          indices_ok = false;
          bad = std::min(bad, id);
          break;
        }
        for (int k = 0; k < 3; ++k) rows[k][lane] = load_vertex(mesh, idx[k]);
      }
      if (!indices_ok) continue;
      __m128 nonfinite = _mm_setzero_ps();  // x * 0 is NaN exactly for NaN / Inf x
      for (int k = 0; k < 3; ++k) {
        _MM_TRANSPOSE4_PS(rows[k][0], rows[k][1], rows[k][2], rows[k][3]);
        for (int a = 0; a < 3; ++a) {
          _mm_storeu_ps(blk.v[k][a], rows[k][a]);
          nonfinite = _mm_add_ps(nonfinite, _mm_mul_ps(rows[k][a], _mm_setzero_ps()));
        }
      }
      if (_mm_movemask_ps(_mm_cmpunord_ps(nonfinite, nonfinite)) != 0)
        for (int lane = 0; lane < 4; ++lane)
          for (int k = 0; k < 3; ++k)
            if (!std::isfinite(blk.v[k][0][lane]) || !std::isfinite(blk.v[k][1][lane]) ||
                !std::isfinite(blk.v[k][2][lane]))
              bad = std::min(bad, lane_id(blk, lane));
    }
    return bad;
  }

  const Scene& scene_;
  MeshStarts starts_;
};
}  // namespace

void refit_accel(Accel& accel, const Scene& scene) {
  refit_accel_cost(accel, scene);
}

double refit_accel_cost(Accel& accel, const Scene& scene) {
  double cost = 0;
  const size_t count = scene.triangle_count();
  if (count != accel.validation.valid.size())
    throw Error(
        ErrorCode::invalid_argument,
        fmt::format("refit: the scene has {} triangles, the accel was built over {}; rebuild",
                    count, accel.validation.valid.size()));
  Bounds3 box;
  switch (accel.layout) {
    case Layout::bvh4:
      cost = refit_wide(accel.nodes->bvh4, BlockRewriter(scene));
      break;
    case Layout::bvh8:
      cost = refit_wide(accel.nodes->bvh8, BlockRewriter(scene));
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
  return cost;
}

}  // namespace kestrel
