// kestrel public API: how many threads the library may use.
#pragma once

namespace kestrel {

/// Limits the library's worker threads while alive (1 = everything runs on the caller's
/// thread). Scopes nest; the innermost wins. Results never depend on the thread count.
class ThreadLimit {
 public:
  explicit ThreadLimit(int thread_count);
  ~ThreadLimit();
  ThreadLimit(const ThreadLimit&) = delete;
  ThreadLimit& operator=(const ThreadLimit&) = delete;

 private:
  void* control_;
};

/// Hardware threads available to the process.
int hardware_thread_count();

}  // namespace kestrel
