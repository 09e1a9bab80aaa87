#include <cstdio>
#include <cstdlib>

#include "core/check.h"
#include "kestrel/error.h"

namespace kestrel {

const char* to_string(ErrorCode code) {
  switch (code) {
    case ErrorCode::invalid_argument:
      return "invalid_argument";
    case ErrorCode::file_not_found:
      return "file_not_found";
    case ErrorCode::parse_error:
      return "parse_error";
    case ErrorCode::invalid_geometry:
      return "invalid_geometry";
    case ErrorCode::unsupported:
      return "unsupported";
    case ErrorCode::io_error:
      return "io_error";
  }
  return "unknown";
}

namespace detail {
void check_failed(const char* expr, const char* file, int line, const std::string& msg) {
  std::fprintf(stderr, "kestrel: internal check failed: %s at %s:%d %s\n", expr, file, line,
               msg.c_str());
  std::abort();
}
}  // namespace detail

}  // namespace kestrel
