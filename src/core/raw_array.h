// A fixed-size array whose elements are not initialised: for large build buffers that are
// fully written before being read, so no time is spent zeroing hundreds of megabytes.
#pragma once
#include <cstddef>
#include <cstdlib>
#include <memory>
#include <new>
#include <type_traits>

#include "core/memory.h"

namespace kestrel {

template <class T>
class RawArray {
  static_assert(std::is_trivially_copyable_v<T> && std::is_trivially_destructible_v<T>,
                "RawArray holds implicit-lifetime types only");

 public:
  RawArray() = default;
  explicit RawArray(size_t n) { resize(n); }
  void resize(size_t n) {
    data_.reset();  // the old block goes back before the new one is taken
    data_ = std::unique_ptr<T[], Free>(
        n ? static_cast<T*>(allocate_buffer(sizeof(T) * n, 64)) : nullptr, Free{sizeof(T) * n});
    size_ = n;
  }
  T& operator[](size_t i) { return data_[i]; }
  const T& operator[](size_t i) const { return data_[i]; }
  T* data() { return data_.get(); }
  const T* data() const { return data_.get(); }
  size_t size() const { return size_; }
  T* begin() { return data(); }
  T* end() { return data() + size_; }
  const T* begin() const { return data(); }
  const T* end() const { return data() + size_; }
  void swap(RawArray& o) {
    data_.swap(o.data_);
    std::swap(size_, o.size_);
  }

 private:
  struct Free {
    size_t bytes = 0;
    void operator()(T* p) const { free_buffer(p, bytes); }
  };
  std::unique_ptr<T[], Free> data_;
  size_t size_ = 0;
};

}  // namespace kestrel
