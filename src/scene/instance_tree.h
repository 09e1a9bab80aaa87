// The top-level tree over instances, built directly in the wide layout from Morton order:
// rebuilt every frame, so its build time is what counts.
#pragma once
#include <span>

#include "core/raw_array.h"
#include "kestrel/trace.h"
#include "traverse/accel_nodes.h"

namespace kestrel {

/// A wide tree whose leaves are single instances: child reference wide_leaf_bit | prim_id
/// of the PrimRef. Instances are sorted by the 30-bit Morton code of their box centre
/// (serial radix sort of packed code/index records); each node splits its sorted range at the
/// highest differing code bit, repeatedly splitting its largest part, until it has W parts (as
/// LBVH, Karras 2012, but emitting wide nodes directly). O(n) after the sort; one thread. Working
/// memory kept between builds (a TLAS is rebuilt every frame: fresh pages cost more than the
/// build).
struct InstanceTreeScratch {
  RawArray<uint64_t> records, tmp;  // Morton code << 32 | ref index, sorted
  RawArray<uint32_t> keys;          // the sorted codes
  Buffer<PrimRef> sorted;
};

/// `centres`: the bounds of r.lo + r.hi over the refs (twice the box centres), which the
/// caller computes while it makes the refs (one pass less).
void build_instance_tree(std::span<const PrimRef> refs, const Bounds3& centres,
                         Buffer<Bvh4Node>& nodes, InstanceTreeScratch& scratch);
void build_instance_tree(std::span<const PrimRef> refs, const Bounds3& centres,
                         Buffer<Bvh8Node>& nodes, InstanceTreeScratch& scratch);

}  // namespace kestrel
