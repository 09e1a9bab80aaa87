// Wide-BVH traversal kernels, written once with GCC vector extensions and compiled once per
// instruction set (kernels_sse2.cpp, kernels_avx2.cpp, kernels_avx512.cpp), each with its
// own -m flags and its own namespace (KESTREL_ISA_NS). Everything here has internal linkage
// and no std template is instantiated, so no ISA-specific code can leak into another file.
//
// Results are bit-identical to the scalar reference (traverse_bvh2.h + watertight_hit):
//  - the triangle test performs the same float operations in the same order (the files are
//    compiled with -ffp-contract=off, so no FMA contraction), including the double-precision
//    retry when an edge function is exactly zero;
//  - box tests compute the entry and exit distances with the same operations as SlabRay, so
//    a node is visited whenever the scalar traversal would reach its leaves;
//  - closest-hit ties resolve to the smallest prim id (closer_hit), so the visiting order
//    does not matter.
#ifndef KESTREL_ISA_NS
#error "define KESTREL_ISA_NS before including wide_kernels.inl"
#endif

#include <immintrin.h>

#include <cstdint>
#include <cstdlib>

#include "traverse/kernels.h"

// Traversal statistics for experiments: a program that defines KESTREL_TRAVERSAL_STATS, the
// counters below, and includes this file with its own KESTREL_ISA_NS gets per-thread counts
// of rays, nodes visited, blocks tested and hit children per node (stat_hist[k] = nodes
// with k children hit). Off in the library.
#ifdef KESTREL_TRAVERSAL_STATS
namespace kestrel::kernels {
extern thread_local uint64_t stat_nodes, stat_blocks, stat_rays, stat_hist[9];
}
#define KSTAT(x) (x)
#else
#define KSTAT(x) ((void)0)
#endif
namespace kestrel::kernels::KESTREL_ISA_NS {
namespace {

// In this order: each part uses the ones before it.
// clang-format off
#include "traverse/wide_tests.inl"
#include "traverse/wide_traversal.inl"
#include "traverse/wide_packet_lanes.inl"
#include "traverse/wide_packets.inl"
#include "traverse/wide_tlas_packets.inl"
#include "traverse/wide_stream_lanes.inl"
// clang-format on

const Table table = {
    &trace_batch<4, false, Bvh4Node>,
    &trace_batch<4, true, Bvh4Node>,
    &trace_packets<4, Bvh4Node>,
    &trace_batch<8, false, Bvh8Node>,
    &trace_batch<8, true, Bvh8Node>,
    &trace_packets<8, Bvh8Node>,
    &trace_tlas<4, false, Bvh4Node>,
    &trace_tlas<4, true, Bvh4Node>,
    &trace_tlas<8, false, Bvh8Node>,
    &trace_tlas<8, true, Bvh8Node>,
    &occlusion_packets<4, Bvh4Node>,
    &occlusion_packets<8, Bvh8Node>,
    &trace_tlas_packets<false>,
    &trace_tlas_packets<true>,
    &trace_streams<4, false, Bvh4Node>,
    &trace_streams<8, false, Bvh8Node>,
    &trace_streams<4, true, Bvh4Node>,
    &trace_streams<8, true, Bvh8Node>,
    &trace_batch<4, true, Bvh4Node, true>,
    &trace_batch<8, true, Bvh8Node, true>,
};

}  // namespace
}  // namespace kestrel::kernels::KESTREL_ISA_NS
