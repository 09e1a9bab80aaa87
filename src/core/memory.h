// Allocation of large, short-lived build buffers. Backed by TBB's scalable allocator, whose
// large-object cache keeps freed blocks for the next build: a BVH rebuilt every frame then
// stops paying page faults for hundreds of megabytes of fresh memory each time.
#pragma once
#include <cstddef>

namespace kestrel {

/// At least `bytes` bytes aligned to `alignment` (a power of two), uninitialised.
/// Throws std::bad_alloc when out of memory.
void* allocate_buffer(size_t bytes, size_t alignment);
/// Frees a block from allocate_buffer (nullptr is fine).
void free_buffer(void* p);

}  // namespace kestrel
