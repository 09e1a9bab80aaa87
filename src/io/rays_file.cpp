// `.rays` / `.hits` interchange files (DESIGN.md), little-endian.
#include <fmt/format.h>

#include <bit>
#include <cstring>
#include <fstream>
#include <limits>

#include "core/file_io.h"
#include "io/loaders.h"
#include "kestrel/error.h"
#include "kestrel/io.h"

namespace kestrel {

static_assert(std::endian::native == std::endian::little, "rays/hits files are little-endian");

namespace {

struct Header {
  char magic[4];
  uint32_t version;
  uint64_t count;
};
static_assert(sizeof(Header) == 16);

template <class Record>
std::vector<Record> read_records(const std::string& path, const char (&magic)[5],
                                 size_t record_size,
                                 void (*decode)(const unsigned char*, Record&)) {
  require_readable_file(path);
  std::ifstream f(path, std::ios::binary);
  f.seekg(0, std::ios::end);
  const uint64_t size = uint64_t(f.tellg());
  f.seekg(0);
  Header h{};
  if (size < sizeof(Header) || !f.read(reinterpret_cast<char*>(&h), sizeof(h)))
    throw Error(ErrorCode::parse_error,
                fmt::format("{}: {} bytes, too short for a header", path, size));
  if (std::memcmp(h.magic, magic, 4) != 0)
    throw Error(ErrorCode::parse_error, fmt::format("{}: magic is not \"{}\"", path, magic));
  if (h.version != 1)
    throw Error(ErrorCode::parse_error,
                fmt::format("{}: version {} (expected 1)", path, h.version));
  const uint64_t expected = sizeof(Header) + h.count * record_size;
  if (h.count > (uint64_t(1) << 40) || size != expected)
    throw Error(ErrorCode::parse_error,
                fmt::format("{}: header says {} records ({} bytes) but the file has {} bytes", path,
                            h.count, expected, size));
  std::vector<unsigned char> bytes(h.count * record_size);
  if (!f.read(reinterpret_cast<char*>(bytes.data()), std::streamsize(bytes.size())))
    throw Error(ErrorCode::parse_error, fmt::format("{}: read failed", path));
  std::vector<Record> out(h.count);
  for (size_t i = 0; i < out.size(); ++i) decode(&bytes[i * record_size], out[i]);
  return out;
}

void write_bytes(const std::string& path, const char (&magic)[5], uint64_t count, const void* data,
                 size_t bytes) {
  AtomicFile f(path);
  Header h{};
  std::memcpy(h.magic, magic, 4);
  h.version = 1;
  h.count = count;
  f.write(&h, sizeof(h));
  f.write(data, bytes);
  f.commit();
}

}  // namespace

std::vector<Ray> read_rays(const std::string& path) {
  return read_records<Ray>(path, "RAYS", 32, [](const unsigned char* p, Ray& r) {
    float f[8];
    std::memcpy(f, p, 32);
    r = Ray{{f[0], f[1], f[2]}, {f[3], f[4], f[5]}, f[6], f[7]};
  });
}

void write_rays(const std::string& path, std::span<const Ray> rays) {
  std::vector<float> data(rays.size() * 8);
  for (size_t i = 0; i < rays.size(); ++i) {
    const Ray& r = rays[i];
    const float f[8] = {r.org.x, r.org.y, r.org.z, r.dir.x, r.dir.y, r.dir.z, r.tmin, r.tmax};
    std::memcpy(&data[i * 8], f, 32);
  }
  write_bytes(path, "RAYS", rays.size(), data.data(), data.size() * 4);
}

std::vector<Hit> read_hits(const std::string& path) {
  return read_records<Hit>(path, "HITS", 8, [](const unsigned char* p, Hit& h) {
    h = Hit{};
    std::memcpy(&h.t, p, 4);
    std::memcpy(&h.prim_id, p + 4, 4);
  });
}

void write_hits(const std::string& path, std::span<const Hit> hits) {
  std::vector<unsigned char> data(hits.size() * 8);
  for (size_t i = 0; i < hits.size(); ++i) {
    const float t = hits[i].hit() ? hits[i].t : std::numeric_limits<float>::infinity();
    std::memcpy(&data[i * 8], &t, 4);
    std::memcpy(&data[i * 8 + 4], &hits[i].prim_id, 4);
  }
  write_bytes(path, "HITS", hits.size(), data.data(), data.size());
}

}  // namespace kestrel
