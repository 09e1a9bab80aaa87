// Checked reads and atomic writes (see file_io.h).
#include "core/file_io.h"

#include <fmt/format.h>
#include <sys/stat.h>
#include <unistd.h>

#include <atomic>
#include <cctype>
#include <cerrno>
#include <cstring>
#include <filesystem>

#include "kestrel/error.h"

namespace kestrel {

namespace {

const char* kind_of(mode_t mode) {
  if (S_ISDIR(mode)) return "a folder";
  if (S_ISFIFO(mode)) return "a FIFO";
  if (S_ISCHR(mode)) return "a character device";
  if (S_ISBLK(mode)) return "a block device";
  if (S_ISSOCK(mode)) return "a socket";
  return "not a regular file";
}

std::string size_text(uint64_t bytes) {
  if (bytes >= (uint64_t(1) << 30))
    return fmt::format("{:.1f} GiB", double(bytes) / double(uint64_t(1) << 30));
  if (bytes >= (uint64_t(1) << 20))
    return fmt::format("{:.1f} MiB", double(bytes) / double(uint64_t(1) << 20));
  return fmt::format("{} bytes", bytes);
}

}  // namespace

uint64_t regular_file_size(const std::string& path, std::string_view what) {
  struct stat st {};
  if (::stat(path.c_str(), &st) != 0)
    throw Error(ErrorCode::file_not_found,
                fmt::format("{}: no such {} ({})", path, what, std::strerror(errno)));
  if (!S_ISREG(st.st_mode)) {
    const bool vowel = !what.empty() && std::strchr("aeiouAEIOU", what.front()) != nullptr;
    throw Error(ErrorCode::file_not_found,
                fmt::format("{}: is {}, not {} {} kestrel can read", path, kind_of(st.st_mode),
                            vowel ? "an" : "a", what));
  }
  return uint64_t(st.st_size);
}

std::string read_bounded_file(const std::string& path, uint64_t max_bytes, std::string_view what) {
  const uint64_t size = regular_file_size(path, what);
  if (size > max_bytes)
    throw Error(ErrorCode::parse_error,
                fmt::format("{}: {} is larger than the {} limit of {}", path, size_text(size), what,
                            size_text(max_bytes)));
  std::FILE* f = std::fopen(path.c_str(), "rb");
  if (!f)
    throw Error(ErrorCode::file_not_found,
                fmt::format("{}: cannot open the {}: {}", path, what, std::strerror(errno)));
  std::string text(size_t(size), '\0');
  const size_t got = size ? std::fread(text.data(), 1, text.size(), f) : 0;
  const bool failed = std::ferror(f);
  std::fclose(f);
  if (failed || got != text.size())
    throw Error(
        ErrorCode::parse_error,
        fmt::format("{}: reading the {} failed after {} of {} bytes", path, what, got, size));
  return text;
}

void check_writable_destination(const std::string& path) {
  if (path.empty()) throw Error(ErrorCode::invalid_argument, "an output file name is empty");
  struct stat st {};
  if (::stat(path.c_str(), &st) == 0 && !S_ISREG(st.st_mode))
    throw Error(ErrorCode::io_error, fmt::format("{}: is {}; outputs are written to regular files",
                                                 path, kind_of(st.st_mode)));
  std::filesystem::path parent = std::filesystem::path(path).parent_path();
  if (parent.empty()) parent = ".";
  struct stat dir {};
  if (::stat(parent.c_str(), &dir) != 0 || !S_ISDIR(dir.st_mode))
    throw Error(ErrorCode::io_error,
                fmt::format("{}: the folder {} does not exist", path, parent.string()));
  if (::access(parent.c_str(), W_OK) != 0)
    throw Error(ErrorCode::io_error,
                fmt::format("{}: the folder {} is not writable", path, parent.string()));
}

void make_directories(const std::string& dir) {
  if (dir.empty()) return;
  std::error_code ec;
  std::filesystem::create_directories(dir, ec);
  if (ec)
    throw Error(ErrorCode::io_error,
                fmt::format("{}: cannot create the folder: {}", dir, ec.message()));
}

void make_parent_directories(const std::string& path) {
  make_directories(std::filesystem::path(path).parent_path().string());
}

std::string lower_extension(const std::string& path) {
  std::string ext = std::filesystem::path(path).extension().string();
  for (char& c : ext) c = char(std::tolower(static_cast<unsigned char>(c)));
  return ext;
}

AtomicFile::AtomicFile(std::string path) : path_(std::move(path)) {
  check_writable_destination(path_);
  static std::atomic<unsigned> counter{0};
  const std::filesystem::path p(path_);
  temp_ = (p.parent_path() / fmt::format(".{}.partial-{}-{}{}", p.filename().string(), ::getpid(),
                                         counter++, p.extension().string()))
              .string();
}

AtomicFile::~AtomicFile() {
  if (file_) std::fclose(file_);
  if (!committed_) std::remove(temp_.c_str());
}

void AtomicFile::open() {
  file_ = std::fopen(temp_.c_str(), "wb");
  if (!file_)
    throw Error(ErrorCode::io_error,
                fmt::format("{}: cannot create a file there: {}", path_, std::strerror(errno)));
}

void AtomicFile::write(const void* data, size_t bytes) {
  if (!file_) open();
  if (bytes && std::fwrite(data, 1, bytes, file_) != bytes)
    throw Error(ErrorCode::io_error,
                fmt::format("{}: write failed: {} (the old file, if any, is kept)", path_,
                            std::strerror(errno ? errno : EIO)));
}

void AtomicFile::commit() {
  if (file_) {
    std::FILE* f = file_;
    file_ = nullptr;
    errno = 0;
    // fflush + fclose report a full disk on the file systems kestrel writes to; no fsync (it
    // would cost every frame of a sequence a disk round trip).
    const bool flushed = std::fflush(f) == 0;
    const int flush_errno = errno;
    const bool closed = std::fclose(f) == 0;
    if (!flushed || !closed)
      throw Error(ErrorCode::io_error,
                  fmt::format("{}: write failed: {} (the old file, if any, is kept)", path_,
                              std::strerror(flush_errno ? flush_errno : EIO)));
  }
  if (std::rename(temp_.c_str(), path_.c_str()) != 0)
    throw Error(ErrorCode::io_error,
                fmt::format("{}: cannot replace the file: {}", path_, std::strerror(errno)));
  committed_ = true;
}

}  // namespace kestrel
