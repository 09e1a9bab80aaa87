// Traversal kernels per instruction set. Each kernels_<isa>.cpp compiles wide_kernels.inl
// with its own compiler flags into its own namespace; trace.cpp picks a table at run time
// (kernel_table, by the ISA a call asks for or default_isa()). Kernels take raw pointers only, so
// no template code is shared between the ISA files (a shared inline function compiled with AVX-512
// could otherwise be picked by the linker for an SSE2 caller).
#pragma once
#include <cstddef>

#include "kestrel/instances.h"
#include "kestrel/trace.h"
#include "traverse/accel_nodes.h"

namespace kestrel::kernels {

/// Traces rays[0..n) into hits[0..n); an untraceable ray (batches.h) gets a miss, except in
/// the ray-stream kernels (stream*, any_stream*), whose rays must be traceable (the caller
/// filters the rest). Closest-hit kernels fill t, prim_id, u, v; any-hit kernels fill t and
/// prim_id.
using Bvh4Fn = void (*)(const Bvh4Node* nodes, const TriangleBlock* blocks, const Ray* rays,
                        Hit* hits, size_t n);
using Bvh8Fn = void (*)(const Bvh8Node* nodes, const TriangleBlock* blocks, const Ray* rays,
                        Hit* hits, size_t n);

/// What the two-level kernels know of an instance (plain data, built by commit()).
struct InstanceData {
  float world_to_object[12];  ///< Affine3::m of the inverse transform
  uint32_t mask;
  uint32_t id;        ///< InstanceId reported in hits
  const void* nodes;  ///< the mesh's Bvh4Node / Bvh8Node array (same width as the TLAS)
  const TriangleBlock* blocks;
};

/// Two-level: TLAS leaves are wide_leaf_bit | index into `instances`. Closest-hit kernels
/// fill every field of InstanceHit; any-hit kernels fill t, prim_id and instance_id. An
/// untraceable ray gets a miss.
using TlasFn = void (*)(const void* tlas_nodes, const InstanceData* instances, const Ray* rays,
                        InstanceHit* hits, size_t n, uint32_t ray_mask);

struct Table {
  Bvh4Fn closest4, any4, packet4;
  Bvh8Fn closest8, any8, packet8;  ///< packet*: closest hit, coherent rays in packets (any n)
  TlasFn tlas_closest4, tlas_any4, tlas_closest8, tlas_any8;
  Bvh4Fn any_packet4;
  Bvh8Fn any_packet8;  ///< any hit, coherent rays in packets (any n)
  /// Two levels (Bvh8 TLAS and BLASes), coherent rays in packets (any n): the same hits as
  /// tlas_closest8 / tlas_any8.
  TlasFn tlas_packet8, tlas_any_packet8;
  /// A large incoherent batch as ray streams (any n; best with thousands of rays): closest hit,
  /// the same hits as closest4 / closest8; any hit, the same answers as any4 / any8.
  Bvh4Fn stream4;
  Bvh8Fn stream8;
  Bvh4Fn any_stream4;
  Bvh8Fn any_stream8;
  /// Any hit visiting children nearest first (any4 / any8: slot order); the same answers.
  Bvh4Fn any_nearest4;
  Bvh8Fn any_nearest8;
};

const Table& table_sse2();
const Table& table_avx2();
const Table& table_avx512();
/// The table of an ISA (the caller checks isa_supported).
const Table& table_for(Isa isa);

}  // namespace kestrel::kernels
