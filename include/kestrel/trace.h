// kestrel public API: rays, hits, an acceleration structure over a scene, and tracing.
#pragma once
#include <cstdint>
#include <limits>
#include <memory>
#include <span>

#include "kestrel/bvh.h"
#include "kestrel/isa.h"
#include "kestrel/scene.h"

namespace kestrel {

/// A ray: points org + t * dir for t in (tmin, tmax). dir need not be normalised; t is in
/// units of dir. A ray with a NaN or Inf component, or a zero direction, never hits.
struct Ray {
  Vec3 org;
  Vec3 dir;
  float tmin = 0.0f;
  float tmax = std::numeric_limits<float>::infinity();
};

/// Id of "no primitive".
inline constexpr uint32_t invalid_id = 0xFFFFFFFFu;

/// A hit: distance t (units of dir) and the global prim id; a miss has t = +inf and
/// prim_id = invalid_id. u, v are barycentrics of vertices 1 and 2.
struct Hit {
  float t = std::numeric_limits<float>::infinity();
  uint32_t prim_id = invalid_id;
  float u = 0, v = 0;
  bool hit() const { return prim_id != invalid_id; }
};

namespace detail {
struct AccelNodes;  // the nodes and triangles of one layout (internal: src/traverse/accel_nodes.h)
}

/// A scene ready to trace: a BVH over its valid triangles in one layout. What it reports is
/// public; its nodes are not (their byte layouts are kestrel's to change).
struct Accel {
  Accel();
  ~Accel();
  Accel(Accel&&) noexcept;
  Accel& operator=(Accel&&) noexcept;

  Layout layout = Layout::bvh2;
  Bounds3 bounds;         ///< of the valid triangles (empty box when none)
  size_t prim_count = 0;  ///< valid triangles in the BVH
  SceneValidation validation;
  /// The builder that made the tree: the configured one, or median when an SAH tree came out
  /// deeper than traversal allows (pathological inputs) and was rebuilt (`depth_fallback`).
  Builder builder = Builder::binned;
  bool depth_fallback = false;
  double build_ms = 0;  ///< prim refs + builder + collapse + triangle blocks, wall
  /// Bytes of the traversal structure: nodes + triangles (+ prim ids for bvh2).
  size_t memory_bytes() const;
  std::unique_ptr<detail::AccelNodes> nodes;  ///< never null
};

/// Builds an Accel over a scene's valid triangles (invalid ones are counted and skipped),
/// in config.layout (automatic: the fastest layout for this machine's instruction set).
Accel build_accel(const Scene& scene, const BuildConfig& config);

/// Refits an Accel to the scene's current vertex positions (same meshes, same triangles,
/// moved vertices): boxes are recomputed bottom-up, the tree topology is kept. Throws
/// Error(invalid_argument) if the triangle count changed or a triangle in the tree got a
/// NaN/Inf vertex or a bad index (bvh2 layout: also a degenerate one); the Accel is then
/// partly refitted and must be rebuilt.
void refit_accel(Accel& accel, const Scene& scene);

/// Per-call choices; empty means the default (the fastest for the machine and ray kind).
struct TraceOptions {
  std::optional<Isa> isa;
  /// Coherent-ray packets (wide layouts; closest and any hit). Default: used for chunks of
  /// rays that look coherent (groups of 8 whose directions share signs and dominant axis:
  /// camera rays, shadow rays towards one light) where packets have been faster than single
  /// rays so far: the Accel times some chunks each way (packets lose where triangles are small
  /// in the image). The hits are the same either way.
  std::optional<bool> packets;
  /// Stream mode (wide layouts): the batch is traced in an order that groups rays by
  /// direction octant, origin and direction (groups of up to 2^20 rays sorted by a 40-bit
  /// key), and each hit is returned in the caller's order: the same hits as single rays.
  /// Over bvh8 with AVX2 or AVX-512 the sorted rays go as ray streams (16 k rays walk the tree
  /// together, each node's boxes tested for 8 or 16 rays at once) unless `packets` is set;
  /// otherwise as packets unless `packets` is false. Default: on for closest-hit batches of at
  /// least 2^18 incoherent rays whose consecutive origins lie far apart (shuffled, compacted or
  /// material-sorted bounces: 1.13-1.77x `rtcIntersect1` with ray streams, docs/benchmarks.md;
  /// without ray streams only over a tree of at least 2 MB); with ray streams, other incoherent
  /// batches of at least 2^16 rays (smaller, or in pixel order) are timed each way by the Accel,
  /// which takes the faster; off otherwise (any hit gains nothing).
  std::optional<bool> stream;
};

/// Closest hit along the ray (watertight, Woop et al. 2013), or a miss. When several
/// triangles are hit at exactly the same t, the smallest prim id wins, so every layout,
/// kernel and thread count returns the same hit.
Hit intersect(const Accel& accel, const Ray& ray);
/// Any hit in (tmin, tmax): t of the hit found (not necessarily the closest), or a miss.
Hit intersect_any(const Accel& accel, const Ray& ray);

/// Traces a batch (closest hit), spread over the current thread pool in chunks.
/// hits.size() must equal rays.size().
void trace(const Accel& accel, std::span<const Ray> rays, std::span<Hit> hits,
           const TraceOptions& options = {});
/// Occlusion for a batch: occluded[i] = 1 when ray i hits anything in (tmin, tmax).
void occluded(const Accel& accel, std::span<const Ray> rays, std::span<uint8_t> occluded,
              const TraceOptions& options = {});
/// Batch closest or any hit into Hits (any hit: t of a hit found, not necessarily nearest).
void trace(const Accel& accel, std::span<const Ray> rays, std::span<Hit> hits, bool any_hit,
           const TraceOptions& options = {});

}  // namespace kestrel
