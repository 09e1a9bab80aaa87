#include "core/parallel.h"

#include <tbb/blocked_range.h>
#include <tbb/global_control.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_invoke.h>
#include <tbb/task_arena.h>

#include <thread>

#include "kestrel/parallel.h"

// ThreadSanitizer cannot see the synchronisation inside libtbb (it is not instrumented), so
// under KESTREL_TSAN the fork and the join are told to it: what the caller wrote before a
// parallel_for happens before every task, and every task before the caller continues.
#if defined(__has_feature)
#if __has_feature(thread_sanitizer)
#define KESTREL_UNDER_TSAN 1
#endif
#endif
#if defined(__SANITIZE_THREAD__) || defined(KESTREL_UNDER_TSAN)
extern "C" void __tsan_acquire(void* address);
extern "C" void __tsan_release(void* address);
#define KESTREL_TSAN_ACQUIRE(a) __tsan_acquire(a)
#define KESTREL_TSAN_RELEASE(a) __tsan_release(a)
#else
#define KESTREL_TSAN_ACQUIRE(a) ((void)(a))
#define KESTREL_TSAN_RELEASE(a) ((void)(a))
#endif

namespace kestrel {

void parallel_for(size_t begin, size_t end, size_t grain, FunctionRef<void(size_t, size_t)> body) {
  if (end <= begin) return;
  if (grain == 0) grain = 1;
  if (end - begin <= grain) {
    body(begin, end);
    return;
  }
  [[maybe_unused]] char fork = 0, join = 0;
  KESTREL_TSAN_RELEASE(&fork);
  tbb::parallel_for(tbb::blocked_range<size_t>(begin, end, grain),
                    [&](const tbb::blocked_range<size_t>& r) {
                      KESTREL_TSAN_ACQUIRE(&fork);
                      body(r.begin(), r.end());
                      KESTREL_TSAN_RELEASE(&join);
                    });
  KESTREL_TSAN_ACQUIRE(&join);
}

void parallel_invoke(FunctionRef<void()> a, FunctionRef<void()> b) {
  [[maybe_unused]] char fork = 0, join = 0;
  KESTREL_TSAN_RELEASE(&fork);
  tbb::parallel_invoke(
      [&] {
        KESTREL_TSAN_ACQUIRE(&fork);
        a();
        KESTREL_TSAN_RELEASE(&join);
      },
      [&] {
        KESTREL_TSAN_ACQUIRE(&fork);
        b();
        KESTREL_TSAN_RELEASE(&join);
      });
  KESTREL_TSAN_ACQUIRE(&join);
}

int current_thread_count() {
  return static_cast<int>(
      tbb::global_control::active_value(tbb::global_control::max_allowed_parallelism));
}

ThreadLimit::ThreadLimit(int thread_count)
    : control_(new tbb::global_control(tbb::global_control::max_allowed_parallelism,
                                       static_cast<size_t>(thread_count < 1 ? 1 : thread_count))) {}

ThreadLimit::~ThreadLimit() {
  delete static_cast<tbb::global_control*>(control_);
}

int hardware_thread_count() {
  unsigned n = std::thread::hardware_concurrency();
  return n == 0 ? 1 : static_cast<int>(n);
}

}  // namespace kestrel
