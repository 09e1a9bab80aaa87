#include "core/memory.h"

#include <tbb/scalable_allocator.h>

#include <new>

namespace kestrel {

void* allocate_buffer(size_t bytes, size_t alignment) {
  void* p = scalable_aligned_malloc(bytes ? bytes : 1, alignment);
  if (!p) throw std::bad_alloc();
  return p;
}

void free_buffer(void* p) {
  if (p) scalable_aligned_free(p);
}

}  // namespace kestrel
