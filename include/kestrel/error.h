// kestrel public API: the one error type the library throws for bad user input.
#pragma once
#include <stdexcept>
#include <string>

namespace kestrel {

/// What kind of user error an Error reports.
enum class ErrorCode {
  invalid_argument,  ///< an API argument or CLI value is out of range or malformed
  file_not_found,    ///< a named file does not exist or cannot be opened
  parse_error,       ///< a file exists but its content is malformed or truncated
  invalid_geometry,  ///< geometry that cannot be used at all (e.g. no valid triangle)
  unsupported,       ///< a valid input that kestrel does not handle
  io_error,          ///< a write failed
};

/// The error the library throws for bad input: a code and a message that names the file,
/// line, object and value at fault. Internal invariant failures are not Errors (see CHECK).
class Error : public std::runtime_error {
 public:
  Error(ErrorCode code, const std::string& message) : std::runtime_error(message), code_(code) {}
  ErrorCode code() const { return code_; }

 private:
  ErrorCode code_;
};

/// Short name of an error code, e.g. "parse_error".
const char* to_string(ErrorCode code);

}  // namespace kestrel
