// Internal invariants. A failed KESTREL_CHECK is a kestrel bug, never a user error: it prints
// the expression, location and message and aborts. User input errors throw kestrel::Error.
#pragma once
#include <string>

namespace kestrel::detail {
[[noreturn]] void check_failed(const char* expr, const char* file, int line,
                               const std::string& msg);
}

#define KESTREL_CHECK(cond, ...)                                                             \
  do {                                                                                       \
    if (!(cond)) ::kestrel::detail::check_failed(#cond, __FILE__, __LINE__, "" __VA_ARGS__); \
  } while (0)
