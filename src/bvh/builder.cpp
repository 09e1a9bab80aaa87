// Builder selection by name or quality, config checks, and the build_bvh() entry point.
#include <fmt/format.h>

#include "bvh/builders.h"
#include "bvh/cost_model.h"
#include "kestrel/error.h"

namespace kestrel {

std::optional<Builder> builder_from_name(const std::string& name) {
  if (name == "median") return Builder::median;
  if (name == "sweep") return Builder::sweep;
  if (name == "binned") return Builder::binned;
  if (name == "lbvh") return Builder::lbvh;
  if (name == "treelet") return Builder::treelet;
  if (name == "spatial") return Builder::spatial;
  return std::nullopt;
}

const char* builder_name(Builder builder) {
  switch (builder) {
    case Builder::median:
      return "median";
    case Builder::sweep:
      return "sweep";
    case Builder::binned:
      return "binned";
    case Builder::lbvh:
      return "lbvh";
    case Builder::treelet:
      return "treelet";
    case Builder::spatial:
      return "spatial";
  }
  return "?";
}

std::optional<BuildQuality> quality_from_name(const std::string& name) {
  if (name == "fast") return BuildQuality::fast;
  if (name == "balanced") return BuildQuality::balanced;
  if (name == "high") return BuildQuality::high;
  if (name == "auto" || name == "automatic") return BuildQuality::automatic;
  return std::nullopt;
}

Builder resolve_builder(const BuildConfig& config, size_t prim_count) {
  if (config.builder) return *config.builder;
  switch (config.quality) {
    case BuildQuality::fast:
      return Builder::lbvh;
    case BuildQuality::balanced:
      return Builder::binned;
    case BuildQuality::high:
      return Builder::spatial;
    case BuildQuality::automatic:
      return choose_builder(prim_count, config.expected_rays);
  }
  return Builder::binned;
}

void check_build_config(const BuildConfig& c) {
  auto bad = [](const std::string& what) {
    throw Error(ErrorCode::invalid_argument, "BuildConfig: " + what);
  };
  if (!(c.traversal_cost >= 0.0f) || !(c.traversal_cost < 1e6f))
    bad(fmt::format("traversal_cost = {} must be finite and >= 0", c.traversal_cost));
  if (!(c.intersection_cost > 0.0f) || !(c.intersection_cost < 1e6f))
    bad(fmt::format("intersection_cost = {} must be finite and > 0", c.intersection_cost));
  if (c.max_leaf_size < 1 || c.max_leaf_size > 255)
    bad(fmt::format("max_leaf_size = {} must be in [1, 255]", c.max_leaf_size));
  if (c.bin_count < 8 || c.bin_count > 32)
    bad(fmt::format("bin_count = {} must be in [8, 32]", c.bin_count));
  if (c.morton_bits != 30 && c.morton_bits != 63)
    bad(fmt::format("morton_bits = {} must be 30 or 63", c.morton_bits));
  if (c.treelet_leaf_count < 3 || c.treelet_leaf_count > 7)
    bad(fmt::format("treelet_leaf_count = {} must be in [3, 7]", c.treelet_leaf_count));
  if (c.treelet_rounds > 16)
    bad(fmt::format("treelet_rounds = {} must be <= 16", c.treelet_rounds));
  if (!(c.expected_rays >= 0.0) || !(c.expected_rays < 1e18))
    bad(fmt::format("expected_rays = {} must be finite and >= 0", c.expected_rays));
}

namespace {

// block_leaves: see build_bvh_for_blocks (the binned and LBVH builders stop at four).
Bvh2 dispatch(std::span<const PrimRef> refs, std::span<const Triangle> triangles,
              const BuildConfig& config, bool block_leaves) {
  check_build_config(config);
  if (refs.empty()) return {};
  if (refs.size() >= 0x7FFFFFFFu)
    throw Error(ErrorCode::unsupported,
                fmt::format("build_bvh: {} primitives exceed 2^31 - 1", refs.size()));
  switch (resolve_builder(config, refs.size())) {
    case Builder::median:
      return build_median(refs, config);
    case Builder::sweep:
      return build_sweep_sah(refs, config);
    case Builder::binned:
      return build_binned_sah(refs, config, block_leaves);
    case Builder::lbvh:
      return build_lbvh(refs, config, block_leaves);
    case Builder::treelet:
      return build_treelet(refs, config);
    case Builder::spatial:
      if (!triangles.empty())
        for (const PrimRef& r : refs)
          if (r.prim_id >= triangles.size())
            throw Error(ErrorCode::invalid_argument,
                        fmt::format("build_bvh: prim id {} has no triangle (of {})", r.prim_id,
                                    triangles.size()));
      return build_spatial_sah(refs, triangles, config, block_leaves);
  }
  return {};
}

}  // namespace

Bvh2 build_bvh(std::span<const PrimRef> refs, const BuildConfig& config) {
  return dispatch(refs, {}, config, false);
}

Bvh2 build_bvh(std::span<const PrimRef> refs, std::span<const Triangle> triangles,
               const BuildConfig& config) {
  return dispatch(refs, triangles, config, false);
}

Bvh2 build_bvh_for_blocks(std::span<const PrimRef> refs, std::span<const Triangle> triangles,
                          const BuildConfig& config) {
  return dispatch(refs, triangles, config, true);
}

}  // namespace kestrel
