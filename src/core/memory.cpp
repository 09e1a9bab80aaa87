#include "core/memory.h"

#include <sys/mman.h>
#include <tbb/scalable_allocator.h>
#include <unistd.h>

#include <algorithm>
#include <cstdint>
#include <mutex>
#include <new>
#include <vector>

#if defined(__SANITIZE_ADDRESS__)
#define KESTREL_ASAN 1
#elif defined(__has_feature)
#if __has_feature(address_sanitizer)
#define KESTREL_ASAN 1
#endif
#endif

namespace kestrel {

namespace {

constexpr size_t huge_page = size_t(2) << 20;
// Freed large blocks kept mapped, at most: an eighth of the machine's memory, within
// [512 MiB, 4 GiB] -- enough for the buffers of several builds of a million triangles or more
// (references, slots, nodes, triangles), so scenes rebuilt every frame, or two builders
// taking turns, reuse their own memory; the oldest blocks are unmapped first beyond it. (A
// fixed 512 MiB made the binned and LBVH builds of the bunny grid, 1.1 M triangles, evict each
// other's blocks: every LBVH build faulted its memory in again, 2.5x its time.)
size_t cache_cap() {
  static const size_t cap = [] {
    const long pages = sysconf(_SC_PHYS_PAGES), page = sysconf(_SC_PAGE_SIZE);
    const size_t ram = pages > 0 && page > 0 ? size_t(pages) * size_t(page) : 0;
    return std::clamp(ram / 8, size_t(512) << 20, size_t(4) << 30);
  }();
  return cap;
}

size_t mapped_size(size_t bytes) {
  return (bytes + huge_page - 1) / huge_page * huge_page;
}

#if defined(KESTREL_ASAN)
// Under AddressSanitizer large blocks are ordinary allocations, so it sees their bounds and
// their use after free.
void* map_block(size_t bytes) {
  return ::operator new(bytes, std::align_val_t(huge_page));
}
void unmap_block(void* p, size_t) {
  ::operator delete(p, std::align_val_t(huge_page));
}
constexpr bool caching = false;
#else
// A 2 MiB-aligned anonymous mapping of `bytes` (a multiple of 2 MiB): mapped with one huge
// page of slack, the misaligned head and the tail unmapped.
void* map_block(size_t bytes) {
  void* raw =
      mmap(nullptr, bytes + huge_page, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS, -1, 0);
  if (raw == MAP_FAILED) throw std::bad_alloc();
  const uintptr_t base = reinterpret_cast<uintptr_t>(raw);
  const uintptr_t aligned = (base + huge_page - 1) & ~(huge_page - 1);
  if (aligned > base) munmap(raw, aligned - base);
  const uintptr_t tail = aligned + bytes, end = base + bytes + huge_page;
  if (end > tail) munmap(reinterpret_cast<void*>(tail), end - tail);
  void* p = reinterpret_cast<void*>(aligned);
  madvise(p, bytes, MADV_HUGEPAGE);  // a hint: without transparent huge pages it does nothing
  return p;
}
void unmap_block(void* p, size_t bytes) {
  munmap(p, bytes);
}
constexpr bool caching = true;
#endif

class LargeBlockPool {
 public:
  void* take(size_t bytes) {
    if (!caching) return map_block(bytes);  // the exact size: the sanitizer sees its end
    bytes = mapped_size(bytes);
    {
      std::lock_guard<std::mutex> lock(mutex_);
      // The most recently freed block of the same mapped size (a scene rebuilt asks for the
      // same sizes again; exact sizes keep give_back free of bookkeeping).
      for (size_t i = free_.size(); i-- > 0;)
        if (free_[i].bytes == bytes) {
          void* p = free_[i].p;
          cached_ -= bytes;
          free_.erase(free_.begin() + ptrdiff_t(i));
          return p;
        }
    }
    return map_block(bytes);
  }

  void give_back(void* p, size_t bytes) noexcept {
    if (!caching) return unmap_block(p, bytes);
    bytes = mapped_size(bytes);
    std::lock_guard<std::mutex> lock(mutex_);  // munmap under the lock: rare and short
    try {
      free_.push_back({p, bytes});
      cached_ += bytes;
    } catch (...) {  // no memory for the list entry: unmapped instead of kept
      unmap_block(p, bytes);
    }
    while (cached_ > cache_cap()) {
      cached_ -= free_.front().bytes;
      unmap_block(free_.front().p, free_.front().bytes);
      free_.erase(free_.begin());
    }
  }

  void release() noexcept {
    std::lock_guard<std::mutex> lock(mutex_);
    for (const Block& e : free_) unmap_block(e.p, e.bytes);
    free_.clear();
    cached_ = 0;
  }
  size_t cached() {
    std::lock_guard<std::mutex> lock(mutex_);
    return cached_;
  }

 private:
  struct Block {
    void* p;
    size_t bytes;
  };
  std::mutex mutex_;
  std::vector<Block> free_;  // oldest first
  size_t cached_ = 0;
};

LargeBlockPool& pool() {
  static LargeBlockPool* p = new LargeBlockPool;  // never destroyed: frees may come at exit
  return *p;
}

}  // namespace

namespace detail {

void* allocate_large_block(size_t bytes) {
  return pool().take(bytes);
}

void free_large_block(void* p, size_t bytes) noexcept {
  if (p) pool().give_back(p, bytes);
}

}  // namespace detail

void release_cached_memory() noexcept {
  pool().release();
}

size_t cached_large_bytes() {
  return pool().cached();
}

size_t large_block_cache_cap() {
  return cache_cap();
}

void* allocate_buffer(size_t bytes, size_t alignment) {
  if (bytes >= detail::large_block_min) return detail::allocate_large_block(bytes);
  void* p = scalable_aligned_malloc(bytes ? bytes : 1, alignment);
  if (!p) throw std::bad_alloc();
  return p;
}

void free_buffer(void* p, size_t bytes) {
  if (!p) return;
  if (bytes >= detail::large_block_min)
    detail::free_large_block(p, bytes);
  else
    scalable_aligned_free(p);
}

}  // namespace kestrel
