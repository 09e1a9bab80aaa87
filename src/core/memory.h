// Allocation of large, short-lived build buffers.
//
// Blocks of at least large_block_min bytes (every BVH build's references, slots, nodes and
// triangles) come from a pool of anonymous mappings aligned to 2 MiB and marked for
// transparent huge pages (one page fault per 2 MiB instead of per 4 KiB: on a virtual machine
// each fault is a trip through the hypervisor). Freed large blocks are kept, up to a cap, and
// handed to the next request of the same size: a BVH rebuilt every frame then touches memory
// that is already mapped. Smaller blocks come from TBB's scalable allocator.
#pragma once
#include <cstddef>

#include "kestrel/buffer.h"

namespace kestrel {

/// At least `bytes` bytes aligned to `alignment` (a power of two, at most 4096),
/// uninitialised. Throws std::bad_alloc when out of memory.
void* allocate_buffer(size_t bytes, size_t alignment);
/// Frees a block from allocate_buffer; `bytes` is the size it was allocated with
/// (nullptr is fine).
void free_buffer(void* p, size_t bytes);

/// Bytes of freed large blocks the pool keeps mapped for reuse (for tests and benchmarks).
size_t cached_large_bytes();
/// The most the pool keeps: an eighth of the machine's memory, within [512 MiB, 4 GiB].
size_t large_block_cache_cap();

}  // namespace kestrel
