// The one parallelism header: parallel_for, parallel_reduce-by-chunks and parallel_invoke.
// TBB stays behind it (parallel.cpp). Below the grain the work runs inline on the caller.
// Callers must make results independent of scheduling (the tests compare 1 vs N threads).
#pragma once
#include <cstddef>
#include <type_traits>
#include <utility>

namespace kestrel {

/// A non-owning reference to a callable (keeps TBB and std::function out of headers).
template <class Sig>
class FunctionRef;
template <class R, class... Args>
class FunctionRef<R(Args...)> {
 public:
  template <class F, class = std::enable_if_t<!std::is_same_v<std::decay_t<F>, FunctionRef>>>
  FunctionRef(F&& f) : obj_(const_cast<void*>(static_cast<const void*>(&f))) {
    call_ = [](void* o, Args... a) -> R {
      return (*static_cast<std::remove_reference_t<F>*>(o))(std::forward<Args>(a)...);
    };
  }
  R operator()(Args... a) const { return call_(obj_, std::forward<Args>(a)...); }

 private:
  void* obj_;
  R (*call_)(void*, Args...);
};

/// Calls body(chunk_begin, chunk_end) over [begin, end) in chunks of about `grain` items,
/// possibly in parallel. Runs inline when end - begin <= grain.
void parallel_for(size_t begin, size_t end, size_t grain, FunctionRef<void(size_t, size_t)> body);

/// Runs a and b, possibly in parallel; returns when both are done.
void parallel_invoke(FunctionRef<void()> a, FunctionRef<void()> b);

/// Number of threads the current scope may use (honours ThreadLimit).
int current_thread_count();

/// Splits [0, n) into `chunk_count(n, grain)` fixed chunks. Use with parallel_for over chunk
/// indices for reductions whose result must not depend on the thread count: reduce each
/// chunk into its own slot, then combine the slots in order.
inline size_t chunk_count(size_t n, size_t grain) {
  return n == 0 ? 0 : (n + grain - 1) / grain;
}

}  // namespace kestrel
