// Stream mode for large incoherent batches: rays are traced in an order that groups similar
// ones (Pharr et al. 1997; Eisenacher et al. 2013 sort by direction and origin), as packets
// or single rays, and every hit is written back to its caller's slot. Hits are the ones single rays
// get: each ray's traversal is exact and independent of its packet mates.
//
// The order is global within groups of up to 2^20 rays: a stable LSD radix sort (8-bit
// digits, so the scatter's 256 streams stay within the TLB) of 40-bit keys - direction octant,
// origin (5 bits per axis, Morton order, within the scene's box), direction (5 + 5 bits of
// the octahedral |x|, |y|), then origin again (4 more bits per axis) - each packed with the
// ray's index. Sorting only within windows of 4-16 k consecutive rays was tried and gained
// nothing on Sponza's diffuse rays: too few rays share a cell there. Measured there (900 k
// rays, one thread): ordering ~50 ms, the random gather and write-back ~70 ms, tracing the
// sorted rays as packets ~240 ms against ~420 ms for the caller's order. Whether the sorted
// chunks go as packets or single rays is timed as the stream runs (trace.cpp: trace_stream).
#pragma once
#include <cstdint>
#include <span>

#include "core/parallel.h"
#include "core/raw_array.h"
#include "kestrel/trace.h"

namespace kestrel {

inline constexpr size_t stream_group = size_t(1) << 20;

/// The default takes the stream for closest-hit batches of at least this many incoherent,
/// unordered rays (trace.cpp: use_stream) over a tree of at least this many bytes.
inline constexpr size_t stream_min_rays = size_t(1) << 18;
inline constexpr size_t stream_min_accel_bytes = size_t(4) << 20;

/// Rays per chunk the stream driver hands to its caller (a stack buffer of hits fits).
inline constexpr size_t stream_chunk = 256;

/// Whether a batch looks coherent (camera rays, shadow rays towards one light): groups of 8
/// consecutive rays whose directions share signs and dominant axis, in 3 of 4 sampled groups.
bool looks_coherent(std::span<const Ray> rays);

/// TraceOptions::stream's default for a batch over a tree of `tree_bytes` bounded by `box`:
/// closest hit, `packets` unset, >= stream_min_rays rays, not coherent, consecutive
/// origins far apart (unordered), tree >= stream_min_accel_bytes. An explicit option wins.
bool stream_by_default(std::span<const Ray> rays, const Bounds3& box, size_t tree_bytes,
                       bool any_hit, const TraceOptions& options);

/// The stream driver: orders each group of the batch (stream_order), gathers chunks of up
/// to stream_chunk rays in that order and calls chunk(rays, callers, n), which traces
/// rays[0, n) and writes hit j to the caller's slot callers[j]. Chunks run in parallel.
void for_each_stream_chunk(
    std::span<const Ray> rays, const Bounds3& box,
    FunctionRef<void(const Ray* rays, const uint32_t* callers, size_t n)> chunk);

/// The trace order of a group (at most stream_group rays): order[i] = caller's index.
/// `scratch` is reused between calls.
void stream_order(std::span<const Ray> rays, const Bounds3& box, RawArray<uint32_t>& order,
                  RawArray<uint64_t>& scratch);

}  // namespace kestrel
