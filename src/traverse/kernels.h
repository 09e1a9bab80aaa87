// Traversal kernels per instruction set. Each kernels_<isa>.cpp compiles wide_kernels.inl
// with its own compiler flags into its own namespace; dispatch.cpp picks a table at run
// time. Kernels take raw pointers only, so no template code is shared between the ISA
// files (a shared inline function compiled with AVX-512 could otherwise be picked by the
// linker for an SSE2 caller).
#pragma once
#include <cstddef>

#include "kestrel/trace.h"

namespace kestrel::kernels {

/// Traces rays[0..n) into hits[0..n). Rays must be traceable (the caller filters the
/// rest). Closest-hit kernels fill t, prim_id, u, v; any-hit kernels fill t and prim_id.
using Bvh4Fn = void (*)(const Bvh4Node* nodes, const TriangleBlock* blocks, const Ray* rays, Hit* hits, size_t n);
using Bvh8Fn = void (*)(const Bvh8Node* nodes, const TriangleBlock* blocks, const Ray* rays, Hit* hits, size_t n);

struct Table {
  Bvh4Fn closest4, any4, packet4;
  Bvh8Fn closest8, any8, packet8;  ///< packet*: closest hit, rays in packets of 8 (any n)
};

const Table& table_sse2();
const Table& table_avx2();
const Table& table_avx512();

}  // namespace kestrel::kernels
