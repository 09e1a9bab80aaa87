// The builders (one file each) behind build_bvh(). Each is a function of the references and
// the config returning the canonical Bvh2; none sees triangles.
#pragma once
#include <span>

#include "kestrel/bvh.h"

namespace kestrel {

Bvh2 build_median(std::span<const PrimRef> refs, const BuildConfig& config);
Bvh2 build_sweep_sah(std::span<const PrimRef> refs, const BuildConfig& config);
Bvh2 build_binned_sah(std::span<const PrimRef> refs, const BuildConfig& config);
Bvh2 build_lbvh(std::span<const PrimRef> refs, const BuildConfig& config);
/// LBVH followed by treelet restructuring (Karras & Aila 2013; US patent 10331632).
Bvh2 build_treelet(std::span<const PrimRef> refs, const BuildConfig& config);

}  // namespace kestrel
