// kestrel public API: primitive references, build configuration, the canonical binary BVH,
// its builders, quality metrics and validation.
#pragma once
#include <cstddef>
#include <cstdint>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "kestrel/buffer.h"
#include "kestrel/types.h"

namespace kestrel {

/// What a builder sees of a primitive: its bounds and its id. 32 bytes, two 16-byte halves
/// (lo + id, hi + spare) so SIMD code loads each half with one aligned load.
struct alignas(16) PrimRef {
  Vec3 lo;
  uint32_t prim_id = 0;
  Vec3 hi;
  uint32_t spare = 0;
};
static_assert(sizeof(PrimRef) == 32);

/// A triangle's vertices: what the spatial-split builder clips, and what an Accel stores for
/// intersection (copied in BVH leaf order).
struct Triangle {
  Vec3 v0, v1, v2;
};

/// The builders, each in its own file under src/bvh/.
enum class Builder {
  median,   ///< equal-count split on the largest centroid axis
  sweep,    ///< full-sweep SAH: exact SAH over all centroid-sorted splits (quality reference)
  binned,   ///< binned SAH (Wald 2007), parallel binning and recursion
  lbvh,     ///< Morton-code linear BVH (Karras 2012), parallel radix sort
  treelet,  ///< LBVH + treelet restructuring (Karras & Aila 2013). Patented: US 10331632.
  spatial,  ///< binned SAH with spatial splits (Stich et al. 2009): a triangle cut by a split
            ///< plane is referenced from both sides with the bounds of its part on each
};

/// For users who don't care which builder: fast = lbvh, balanced = binned, high = spatial;
/// automatic = the builder with the highest effective throughput for the number of rays the
/// caller will trace per build (BuildConfig::expected_rays), from a fitted cost model (see
/// predicted_seconds). No quality maps to `treelet` (patented, opt-in only).
enum class BuildQuality { fast, balanced, high, automatic };

/// Memory layout an Accel traces: the binary tree (scalar reference traversal) or a wide
/// tree collapsed from it (SIMD traversal). `automatic` picks the fastest for the machine.
enum class Layout { automatic, bvh2, bvh4, bvh8 };
/// Parses "auto", "bvh2", "bvh4", "bvh8".
std::optional<Layout> layout_from_name(const std::string& name);
const char* layout_name(Layout layout);

/// Build parameters. Costs are in units of one ray–box-pair test; areas are surface areas.
struct BuildConfig {
  std::optional<Builder> builder;  ///< explicit builder; when empty `quality` decides
  BuildQuality quality = BuildQuality::balanced;
  float traversal_cost = 1.0f;        ///< Ct: cost of visiting an inner node (2 box tests)
  float intersection_cost = 1.0f;     ///< Ci: cost of one ray-triangle test
  uint32_t max_leaf_size = 8;         ///< primitives per leaf, at most (1..255)
  uint32_t bin_count = 32;            ///< binned: bins per axis at the top levels (8..32;
                                      ///< nodes of n primitives use max(8, min(n/4, this)))
  uint32_t morton_bits = 30;          ///< lbvh/treelet: 30 (10 per axis) or 63 (21 per axis)
  uint32_t treelet_leaf_count = 7;    ///< treelet: leaves per treelet (3..7)
  uint32_t treelet_rounds = 3;        ///< treelet: bottom-up restructuring passes
  size_t parallel_threshold = 4096;   ///< subtrees smaller than this build on one task
  Layout layout = Layout::automatic;  ///< build_accel: the layout the Bvh2 becomes
  double expected_rays = 1e6;         ///< quality automatic: rays traced per build
};

/// Canonical binary BVH node, 32 bytes = one half cache line. The two 16-byte rows are the
/// box corners, each padded with an integer so a node loads as two aligned 128-bit vectors.
/// Inner node: count == 0, children at nodes[index] and nodes[index + 1] (siblings adjacent,
/// so one index serves both). Leaf: count > 0 primitives at prim_ids[index .. index+count).
struct alignas(32) Bvh2Node {
  Vec3 lo;
  uint32_t index = 0;
  Vec3 hi;
  uint32_t count = 0;
  bool is_leaf() const { return count != 0; }
};
static_assert(sizeof(Bvh2Node) == 32);

/// The canonical binary BVH: nodes[0] is the root (when non-empty); leaves reference
/// contiguous runs of prim_ids. Every other layout is a conversion of this one.
struct Bvh2 {
  Buffer<Bvh2Node> nodes;
  std::vector<uint32_t> prim_ids;
  bool empty() const { return nodes.empty(); }
};

/// Parses "median", "sweep", "binned", "lbvh", "treelet", "spatial"; nullopt otherwise.
std::optional<Builder> builder_from_name(const std::string& name);
/// The name of a builder, as builder_from_name accepts it.
const char* builder_name(Builder builder);
/// Parses "fast", "balanced", "high", "auto".
std::optional<BuildQuality> quality_from_name(const std::string& name);
/// The builder a config resolves to (its explicit builder, else the quality's; automatic
/// needs the primitive count).
Builder resolve_builder(const BuildConfig& config, size_t prim_count = 0);

/// Throws Error(invalid_argument) naming the field if a config value is out of range.
void check_build_config(const BuildConfig& config);

/// Builds a Bvh2 over the references with the configured builder. An empty span gives an
/// empty Bvh2. References must have finite bounds (make_prim_refs guarantees it).
/// The `spatial` builder given references alone cuts their boxes, not the triangles in them
/// (valid, but loose): pass the triangles for the tight parts it is for.
Bvh2 build_bvh(std::span<const PrimRef> refs, const BuildConfig& config);
/// build_bvh with the triangles the references bound (triangles[prim_id]), which the
/// `spatial` builder clips at its split planes; the other builders ignore them. With spatial
/// splits a primitive may sit in several leaves: prim_ids may be longer than refs.
Bvh2 build_bvh(std::span<const PrimRef> refs, std::span<const Triangle> triangles,
               const BuildConfig& config);

/// Quality figures of a Bvh2.
struct BvhMetrics {
  double sah_cost = 0;       ///< with the config's Ct and Ci, normalised by root area
  double sah_cost_unit = 0;  ///< with Ct = Ci = 1
  size_t node_count = 0;
  size_t inner_count = 0;
  size_t leaf_count = 0;
  size_t prim_count = 0;
  uint32_t max_depth = 0;
  double mean_leaf_depth = 0;
  std::vector<size_t> leaf_size_histogram;  ///< [k] = number of leaves with k primitives
  double bytes_per_prim = 0;                ///< nodes + prim ids
};

/// Depth of the deepest leaf (the root is at depth 0); 0 for an empty tree.
uint32_t max_depth(const Bvh2& bvh);

/// Computes SAH cost (Goldsmith & Salmon / MacDonald & Booth), counts, depth, leaf sizes.
BvhMetrics compute_metrics(const Bvh2& bvh, const BuildConfig& config);

/// Checks every invariant against the references it was built from: each primitive exactly
/// once, child boxes inside the parent's, leaf boxes enclose their primitives, no cycles or
/// shared nodes, leaf sizes within [1, max_leaf_size]. Returns an empty string when valid,
/// else a description of the first violation. split_references (trees of the `spatial`
/// builder): each primitive at least once and at most once per leaf, and a leaf box need
/// only overlap the primitive's box (it bounds a part of it).
std::string validate_bvh(const Bvh2& bvh, std::span<const PrimRef> refs, uint32_t max_leaf_size,
                         bool split_references = false);

}  // namespace kestrel
