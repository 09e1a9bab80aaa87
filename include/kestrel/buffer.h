// kestrel public API: the vector type for large arrays of plain records.
#pragma once
#include <cstddef>
#include <memory>
#include <new>
#include <utility>
#include <vector>

namespace kestrel {

namespace detail {
/// Blocks of at least this many bytes come from kestrel's pool of huge-page mappings, which
/// keeps freed blocks for the next build (src/core/memory.h); smaller ones from operator new.
inline constexpr size_t large_block_min = size_t(1) << 20;
void* allocate_large_block(size_t bytes);
void free_large_block(void* p, size_t bytes) noexcept;
}  // namespace detail

/// Unmaps the large blocks kestrel keeps for reuse after a build (up to an eighth of the
/// machine's memory, within 512 MiB .. 4 GiB; see src/core/memory.cpp). For applications
/// that are done building BVHs for a while.
void release_cached_memory() noexcept;

/// std::allocator that leaves elements uninitialised on resize(n) (it skips the value
/// initialisation std::vector would do). For arrays of plain records -- BVH nodes,
/// primitive references, triangles -- that kestrel always fills completely right after
/// sizing: zeroing hundreds of megabytes first would cost a tenth of a build.
template <class T>
struct UninitializedAllocator : std::allocator<T> {
  using value_type = T;
  template <class U>
  struct rebind {
    using other = UninitializedAllocator<U>;
  };
  UninitializedAllocator() = default;
  template <class U>
  UninitializedAllocator(const UninitializedAllocator<U>&) noexcept {}
  T* allocate(size_t n) {
    if (n > size_t(-1) / sizeof(T)) throw std::bad_array_new_length();
    if (n * sizeof(T) >= detail::large_block_min)
      return static_cast<T*>(detail::allocate_large_block(n * sizeof(T)));
    return std::allocator<T>::allocate(n);
  }
  void deallocate(T* p, size_t n) noexcept {
    if (n * sizeof(T) >= detail::large_block_min)
      detail::free_large_block(p, n * sizeof(T));
    else
      std::allocator<T>::deallocate(p, n);
  }
  template <class U>
  void construct(U*) noexcept {}  // no value-initialisation: the caller writes every element
  template <class U, class... Args>
  void construct(U* p, Args&&... args) {
    ::new (static_cast<void*>(p)) U(std::forward<Args>(args)...);
  }
};
template <class T, class U>
bool operator==(const UninitializedAllocator<T>&, const UninitializedAllocator<U>&) {
  return true;
}

/// A std::vector whose resize(n) does not initialise the new elements (see above);
/// push_back, assignment and copies behave as usual.
template <class T>
using Buffer = std::vector<T, UninitializedAllocator<T>>;

}  // namespace kestrel
