// Files at the boundary: what kestrel opens and writes, checked so hostile paths and full
// disks give a clear Error instead of a hang, a blow-up or a damaged file.
//
// Reading: only regular files are opened (a folder, FIFO or device is an Error naming what
// it is: a FIFO would block forever, /dev/zero would be read until memory runs out), and
// whole-file reads are bounded by a limit the caller states.
// Writing: an AtomicFile writes to a temporary file in the destination's folder and renames
// it over the destination only when every write and the close succeeded, so a failed run
// (full disk, killed process, bad input found late) leaves the old file as it was. A
// destination that exists and is not a regular file (/dev/full, a folder) is refused.
#pragma once
#include <cstdint>
#include <cstdio>
#include <string>
#include <string_view>

namespace kestrel {

/// The size of a regular file; Error(file_not_found) naming the file when it does not exist
/// or is a folder, FIFO, socket or device. `what` names the role ("scene", "weights") in the
/// message.
uint64_t regular_file_size(const std::string& path, std::string_view what = "file");

/// A whole regular file; Error naming the file when it is larger than max_bytes (before
/// reading it) or cannot be read.
std::string read_bounded_file(const std::string& path, uint64_t max_bytes,
                              std::string_view what = "file");

/// Whether a + b and a * b fit in 64 bits (for sizes read from files).
inline bool add_fits(uint64_t a, uint64_t b, uint64_t& sum) {
  return !__builtin_add_overflow(a, b, &sum);
}
inline bool mul_fits(uint64_t a, uint64_t b, uint64_t& product) {
  return !__builtin_mul_overflow(a, b, &product);
}

/// Throws Error(io_error) unless `path` can be written as a regular file: its folder exists
/// and it is not an existing folder, FIFO or device. (For commands that write several files:
/// check them all before the work starts.)
void check_writable_destination(const std::string& path);

/// Creates folder `dir` and its parents where missing (nothing for an empty name); an Error
/// naming the folder and the reason (a file in the way, no permission) where that fails.
void make_directories(const std::string& dir);

/// make_directories of the folder that holds `path`.
void make_parent_directories(const std::string& path);

/// `path`'s extension in lower case, with its dot (".exr"; "" without one).
std::string lower_extension(const std::string& path);

/// A file written under a temporary name and renamed into place by commit().
class AtomicFile {
 public:
  /// Checks the destination (check_writable_destination) and picks the temporary name
  /// (".<name>.partial-<pid>-<n><extension>" beside it; the extension kept for libraries that
  /// look at it).
  explicit AtomicFile(std::string path);
  ~AtomicFile();  ///< removes the temporary file unless committed
  AtomicFile(const AtomicFile&) = delete;
  AtomicFile& operator=(const AtomicFile&) = delete;

  const std::string& path() const { return path_; }
  const std::string& temp_path() const { return temp_; }

  /// Opens the temporary file for writing through write() (for writers of our own).
  void open();
  /// Writes bytes; Error(io_error) naming the destination on a short write (full disk).
  void write(const void* data, size_t bytes);
  void write(std::string_view text) { write(text.data(), text.size()); }
  /// Flushes and closes what open() opened (if any), checking both, then renames the
  /// temporary file over the destination. For files written by a library to temp_path(),
  /// call commit() after the library closed the file.
  void commit();

 private:
  std::string path_, temp_;
  std::FILE* file_ = nullptr;
  bool committed_ = false;
};

}  // namespace kestrel
