#include "core/parallel.h"

#include <tbb/blocked_range.h>
#include <tbb/global_control.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_invoke.h>
#include <tbb/task_arena.h>

#include <thread>

#include "kestrel/parallel.h"

namespace kestrel {

void parallel_for(size_t begin, size_t end, size_t grain, FunctionRef<void(size_t, size_t)> body) {
  if (end <= begin) return;
  if (grain == 0) grain = 1;
  if (end - begin <= grain) {
    body(begin, end);
    return;
  }
  tbb::parallel_for(tbb::blocked_range<size_t>(begin, end, grain),
                    [&](const tbb::blocked_range<size_t>& r) { body(r.begin(), r.end()); });
}

void parallel_invoke(FunctionRef<void()> a, FunctionRef<void()> b) {
  tbb::parallel_invoke([&] { a(); }, [&] { b(); });
}

int current_thread_count() {
  return static_cast<int>(
      tbb::global_control::active_value(tbb::global_control::max_allowed_parallelism));
}

ThreadLimit::ThreadLimit(int thread_count)
    : control_(new tbb::global_control(tbb::global_control::max_allowed_parallelism,
                                       static_cast<size_t>(thread_count < 1 ? 1 : thread_count))) {}

ThreadLimit::~ThreadLimit() { delete static_cast<tbb::global_control*>(control_); }

int hardware_thread_count() {
  unsigned n = std::thread::hardware_concurrency();
  return n == 0 ? 1 : static_cast<int>(n);
}

}  // namespace kestrel
