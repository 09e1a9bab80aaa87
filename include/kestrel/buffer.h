// kestrel public API: the vector type for large arrays of plain records.
#pragma once
#include <memory>
#include <new>
#include <utility>
#include <vector>

namespace kestrel {

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
