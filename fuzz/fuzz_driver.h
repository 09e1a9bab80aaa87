// The shared part of kestrel's fuzz harnesses. Each harness defines fuzz_one(path, bytes):
// the input is written to a file with the reader's extension (kestrel's readers take paths),
// the reader runs, and kestrel::Error -- the clear, named error a user sees -- is the expected
// way to fail. Anything else is a finding: a crash or sanitizer report (libFuzzer stops), or
// another exception (a std:: message would reach the user), which aborts here.
//
// Built with libFuzzer (KESTREL_FUZZ=ON, clang) the harness is a fuzzer; built without it,
// the same file is a replay program that runs every file or folder given on the command line
// once (ctest runs the seed corpora and every input that once failed through it).
#pragma once
#include <dirent.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <exception>
#include <string>
#include <vector>

#include "kestrel/error.h"
#include "kestrel/parallel.h"

namespace kestrel::fuzz {

/// What a harness does with one input, already written to `path` (its data in `bytes`).
void fuzz_one(const std::string& path, const std::string& bytes);
/// The file name the input is written to (the extension picks the reader).
extern const char* const input_name;

inline std::string scratch_dir() {
  static const std::string dir = [] {
    struct stat st {};
    const std::string base = ::stat("/dev/shm", &st) == 0 ? "/dev/shm" : "/tmp";
    // Named by the harness, not the process: a seeded run then sees the same paths (they
    // appear in error messages, whose comparisons steer the fuzzer) every time.
    std::string d = base + "/kestrel_fuzz_" + std::string(input_name);
    ::mkdir(d.c_str(), 0700);
    return d;
  }();
  return dir;
}

inline void write_file(const std::string& path, const std::string& bytes) {
  std::FILE* f = std::fopen(path.c_str(), "wb");
  if (!f) std::abort();
  if (!bytes.empty()) std::fwrite(bytes.data(), 1, bytes.size(), f);
  std::fclose(f);
}

inline int run_input(const uint8_t* data, size_t size) {
  // One thread: coverage then depends on the input alone, so a seeded run is reproducible.
  static const ThreadLimit one_thread(1);
  const std::string bytes(reinterpret_cast<const char*>(data), size);
  const std::string path = scratch_dir() + "/" + input_name;
  write_file(path, bytes);
  try {
    fuzz_one(path, bytes);
  } catch (const kestrel::Error&) {
    // the expected failure: a clear message naming the file
  } catch (const std::exception& e) {
    std::fprintf(stderr, "fuzz: a non-kestrel exception escaped: %s\n", e.what());
    std::abort();
  }
  return 0;
}

}  // namespace kestrel::fuzz

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  return kestrel::fuzz::run_input(data, size);
}

#ifndef KESTREL_LIBFUZZER
// Replay: every file named, and every file in every folder named.
inline std::vector<std::string> replay_inputs(int argc, char** argv) {
  std::vector<std::string> files;
  for (int i = 1; i < argc; ++i) {
    struct stat st {};
    if (::stat(argv[i], &st) != 0) continue;
    if (S_ISDIR(st.st_mode)) {
      if (DIR* d = ::opendir(argv[i])) {
        while (dirent* e = ::readdir(d))
          if (e->d_name[0] != '.') files.push_back(std::string(argv[i]) + "/" + e->d_name);
        ::closedir(d);
      }
    } else {
      files.push_back(argv[i]);
    }
  }
  return files;
}

int main(int argc, char** argv) {
  size_t n = 0;
  for (const std::string& f : replay_inputs(argc, argv)) {
    std::FILE* in = std::fopen(f.c_str(), "rb");
    if (!in) continue;
    std::string bytes;
    char buf[65536];
    for (size_t got; (got = std::fread(buf, 1, sizeof buf, in)) > 0;) bytes.append(buf, got);
    std::fclose(in);
    LLVMFuzzerTestOneInput(reinterpret_cast<const uint8_t*>(bytes.data()), bytes.size());
    ++n;
  }
  std::printf("replayed %zu inputs\n", n);
  return n > 0 ? 0 : 1;
}
#endif
