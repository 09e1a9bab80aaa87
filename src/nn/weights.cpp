// The kestrel weights file (format v1, docs/denoiser.md): magic, version, architecture,
// named tensors, FNV-1a 64 checksum. Shared by every network (denoiser, upsampler).
#include "nn/weights.h"

#include <fmt/format.h>

#include <cmath>
#include <cstring>

#include "core/file_io.h"
#include "kestrel/error.h"

namespace kestrel::nn {

namespace {

constexpr uint32_t kVersion = 1;

uint64_t fnv1a(const uint8_t* p, size_t n) {
  uint64_t h = 0xcbf29ce484222325ull;
  for (size_t i = 0; i < n; ++i) h = (h ^ p[i]) * 0x100000001b3ull;
  return h;
}

struct Reader {
  const std::string& path;
  const std::vector<uint8_t>& bytes;
  size_t at = 0, end = 0;
  template <class T>
  T get(const char* what) {
    if (end - at < sizeof(T))
      throw Error(ErrorCode::parse_error,
                  fmt::format("{}: truncated weights file (reading {})", path, what));
    T v;
    std::memcpy(&v, bytes.data() + at, sizeof v);
    at += sizeof v;
    return v;
  }
};

ConvLayer read_layer(Reader& r, const std::string& name, int cout, int cin, int k) {
  ConvLayer layer;
  const int stride = (cout + 15) / 16 * 16;  // stored output channels: whole 16-wide blocks
  layer.cin = cin, layer.cout = stride, layer.outputs = cout, layer.ksize = k;
  for (const bool is_bias : {false, true}) {
    const std::string want = name + (is_bias ? ".bias" : ".weight");
    const uint32_t len = r.get<uint32_t>("a tensor name length");
    if (len > 256 || r.end - r.at < len)
      throw Error(ErrorCode::parse_error,
                  fmt::format("{}: corrupt tensor name (expected '{}')", r.path, want));
    const std::string got(reinterpret_cast<const char*>(r.bytes.data() + r.at), len);
    r.at += len;
    if (got != want)
      throw Error(ErrorCode::parse_error,
                  fmt::format("{}: expected tensor '{}', found '{}' (not this network's weights)",
                              r.path, want, got));
    const uint32_t ndim = r.get<uint32_t>("a tensor rank");
    std::vector<uint32_t> dims;
    for (uint32_t i = 0; i < ndim && i < 8; ++i) dims.push_back(r.get<uint32_t>("a tensor shape"));
    const std::vector<uint32_t> expect =
        is_bias ? std::vector<uint32_t>{uint32_t(cout)}
                : std::vector<uint32_t>{uint32_t(cout), uint32_t(cin), uint32_t(k), uint32_t(k)};
    if (dims != expect)
      throw Error(ErrorCode::parse_error,
                  fmt::format("{}: tensor '{}' has shape [{}], this network needs [{}]", r.path,
                              want, fmt::join(dims, ","), fmt::join(expect, ",")));
    size_t count = 1;
    for (uint32_t d : dims) count *= d;
    if ((r.end - r.at) / sizeof(float) < count)
      throw Error(ErrorCode::parse_error,
                  fmt::format("{}: truncated weights file (tensor '{}')", r.path, want));
    std::vector<float> v(count);
    std::memcpy(v.data(), r.bytes.data() + r.at, count * sizeof(float));
    r.at += count * sizeof(float);
    for (float f : v)
      if (!std::isfinite(f))
        throw Error(ErrorCode::parse_error,
                    fmt::format("{}: tensor '{}' holds NaN or Inf", r.path, want));
    if (is_bias) {
      layer.bias = std::move(v);
      layer.bias.resize(size_t(stride), 0.0f);
    } else {  // [cout][cin][ky][kx] -> [ky][kx][cin][stride], zero beyond cout
      layer.weights.assign(size_t(k * k) * size_t(cin) * size_t(stride), 0.0f);
      for (int co = 0; co < cout; ++co)
        for (int ci = 0; ci < cin; ++ci)
          for (int t = 0; t < k * k; ++t)
            layer.weights[(size_t(t) * size_t(cin) + size_t(ci)) * size_t(stride) + size_t(co)] =
                v[(size_t(co) * size_t(cin) + size_t(ci)) * size_t(k * k) + size_t(t)];
    }
  }
  return layer;
}

}  // namespace

std::vector<ConvLayer> load_layers(const std::string& path, const char (&magic)[9],
                                   uint32_t architecture, const std::vector<LayerSpec>& specs,
                                   const char* what) {
  // Only a regular file of sane size: a FIFO would block, /dev/zero would never end.
  const std::string text =
      read_bounded_file(path, uint64_t(256) << 20, fmt::format("{} weights file", what));
  const std::vector<uint8_t> bytes(text.begin(), text.end());
  if (bytes.size() < 8 + 12 + 8 || std::memcmp(bytes.data(), magic, 8) != 0)
    throw Error(ErrorCode::parse_error,
                fmt::format("{}: not a kestrel {} weights file (bad magic)", path, what));
  Reader r{path, bytes, 8, bytes.size() - 8};
  const uint32_t version = r.get<uint32_t>("the version");
  if (version != kVersion)
    throw Error(ErrorCode::parse_error,
                fmt::format("{}: weights format version {}, this build reads version {}", path,
                            version, kVersion));
  const uint32_t arch = r.get<uint32_t>("the architecture");
  if (arch != architecture)
    throw Error(ErrorCode::parse_error,
                fmt::format("{}: architecture {}, this build runs architecture {}", path, arch,
                            architecture));
  uint64_t stored;
  std::memcpy(&stored, bytes.data() + bytes.size() - 8, 8);
  if (stored != fnv1a(bytes.data(), bytes.size() - 8))
    throw Error(ErrorCode::parse_error,
                fmt::format("{}: checksum mismatch (the file is corrupt or truncated)", path));
  const uint32_t tensors = r.get<uint32_t>("the tensor count");
  if (tensors != 2 * specs.size())
    throw Error(ErrorCode::parse_error, fmt::format("{}: {} tensors, this network has {}", path,
                                                    tensors, 2 * specs.size()));
  std::vector<ConvLayer> layers;
  for (const LayerSpec& s : specs) layers.push_back(read_layer(r, s.name, s.cout, s.cin, s.ksize));
  if (r.at != r.end)
    throw Error(ErrorCode::parse_error,
                fmt::format("{}: {} unexpected bytes after the tensors", path, r.end - r.at));
  return layers;
}

}  // namespace kestrel::nn
