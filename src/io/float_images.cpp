// Float image files: PFM (the layout Open Image Denoise's tools read), multi-layer OpenEXR,
// and Radiance HDR / 8-bit images (stb_image) for environments.
#include <fmt/format.h>

#include <Iex.h>
#include <ImfChannelList.h>
#include <ImfFrameBuffer.h>
#include <ImfHeader.h>
#include <ImfInputFile.h>
#include <ImfOutputFile.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <memory>

#include "core/file_io.h"
#include "io/loaders.h"
#include "kestrel/error.h"
#include "kestrel/io.h"

namespace kestrel {

namespace {

void check_image(const std::string& path, const FloatImage& image) {
  if (image.width <= 0 || image.height <= 0 || image.channels <= 0 ||
      image.pixels.size() != size_t(image.width) * size_t(image.height) * size_t(image.channels))
    throw Error(ErrorCode::invalid_argument,
                fmt::format("{}: {} floats is not a {}x{}x{} image", path, image.pixels.size(),
                            image.width, image.height, image.channels));
}

}  // namespace

void check_decoded_size(const std::string& path, uint64_t decoded_bytes, uint64_t file_bytes) {
  // Deflate (PNG, EXR ZIP) cannot expand more than ~1032:1; anything claiming more is hostile.
  const uint64_t limit = std::max<uint64_t>(uint64_t(64) << 20, file_bytes * 1100);
  if (decoded_bytes > limit)
    throw Error(ErrorCode::parse_error,
                fmt::format("{}: the image would decode to {} MiB from a {}-byte file (limit {} "
                            "MiB): corrupt or hostile",
                            path, decoded_bytes >> 20, file_bytes, limit >> 20));
}

void write_pfm(const std::string& path, const FloatImage& image) {
  check_image(path, image);
  if (image.channels > 3)
    throw Error(ErrorCode::invalid_argument,
                fmt::format("{}: PFM holds 1 or 3 channels, not {}", path, image.channels));
  const int out_channels = image.channels == 1 ? 1 : 3;
  AtomicFile f(path);
  f.write(
      fmt::format("{}\n{} {}\n-1.0\n", out_channels == 1 ? "Pf" : "PF", image.width, image.height));
  std::vector<float> row(size_t(image.width) * size_t(out_channels), 0.0f);
  for (int y = image.height - 1; y >= 0; --y) {
    for (int x = 0; x < image.width; ++x)
      for (int c = 0; c < image.channels; ++c)
        row[size_t(x) * size_t(out_channels) + size_t(c)] = image.at(x, y)[c];
    f.write(row.data(), row.size() * sizeof(float));
  }
  f.commit();
}

FloatImage read_pfm(const std::string& path) {
  const uint64_t file_bytes = regular_file_size(path, "PFM image");
  std::ifstream f(path, std::ios::binary);
  std::string magic;
  long long w = 0, h = 0;
  double scale = 0;
  f >> magic >> w >> h >> scale;
  if (!f || (magic != "PF" && magic != "Pf"))
    throw Error(ErrorCode::parse_error,
                fmt::format("{}: not a PFM file (header '{}')", path, magic));
  if (w <= 0 || h <= 0 || w > (1 << 16) || h > (1 << 16) || scale == 0 || !std::isfinite(scale))
    throw Error(ErrorCode::parse_error,
                fmt::format("{}: bad PFM header ({} x {}, scale {})", path, w, h, scale));
  f.get();  // the single whitespace after the scale
  const uint64_t pixel_bytes =
      uint64_t(w) * uint64_t(h) * (magic == "PF" ? 3u : 1u) * sizeof(float);
  if (uint64_t(f.tellg()) + pixel_bytes > file_bytes)  // before allocating what the header claims
    throw Error(ErrorCode::parse_error, fmt::format("{}: truncated PFM: the header says {} x {} "
                                                    "({} bytes of pixels), the file has {} bytes",
                                                    path, w, h, pixel_bytes, file_bytes));
  FloatImage image(int(w), int(h), magic == "PF" ? 3 : 1);
  const size_t row_floats = size_t(w) * size_t(image.channels);
  std::vector<float> row(row_floats);
  const bool swap = (scale > 0) != (std::endian::native == std::endian::big);
  for (int y = int(h) - 1; y >= 0; --y) {
    f.read(reinterpret_cast<char*>(row.data()), std::streamsize(row_floats * sizeof(float)));
    if (f.gcount() != std::streamsize(row_floats * sizeof(float)))
      throw Error(ErrorCode::parse_error,
                  fmt::format("{}: truncated PFM ({} x {} x {} floats expected)", path, w, h,
                              image.channels));
    if (swap)
      for (float& v : row) v = std::bit_cast<float>(__builtin_bswap32(std::bit_cast<uint32_t>(v)));
    std::memcpy(image.at(0, y), row.data(), row_floats * sizeof(float));
  }
  return image;
}

void write_exr(const std::string& path, std::span<const ImageLayer> layers) {
  if (layers.empty())
    throw Error(ErrorCode::invalid_argument, fmt::format("{}: no layer to write", path));
  const int w = layers[0].image.width, h = layers[0].image.height;
  for (const ImageLayer& l : layers) {
    check_image(path, l.image);
    if (l.image.width != w || l.image.height != h)
      throw Error(ErrorCode::invalid_argument,
                  fmt::format("{}: layer '{}' is {}x{}, the first layer {}x{}", path, l.name,
                              l.image.width, l.image.height, w, h));
    if (l.channel_names.size() != size_t(l.image.channels))
      throw Error(ErrorCode::invalid_argument,
                  fmt::format("{}: layer '{}' names {} channels for {}", path, l.name,
                              l.channel_names.size(), l.image.channels));
  }
  try {
    Imf::Header header(w, h);
    header.compression() = Imf::ZIP_COMPRESSION;
    Imf::FrameBuffer fb;
    for (const ImageLayer& l : layers) {
      for (int c = 0; c < l.image.channels; ++c) {
        const bool bare = l.name.empty() || l.name == "color";
        const std::string name =
            bare ? l.channel_names[size_t(c)] : l.name + "." + l.channel_names[size_t(c)];
        header.channels().insert(name, Imf::Channel(Imf::FLOAT));
        const size_t xs = sizeof(float) * size_t(l.image.channels);
        fb.insert(name,
                  Imf::Slice(Imf::FLOAT, (char*)(l.image.pixels.data() + c), xs, xs * size_t(w)));
      }
    }
    AtomicFile out(path);
    {
      Imf::OutputFile file(out.temp_path().c_str(), header);
      file.setFrameBuffer(fb);
      file.writePixels(h);
    }  // closed here: OpenEXR throws on a failed write (full disk)
    out.commit();
  } catch (const Error&) {
    throw;
  } catch (const std::exception& e) {
    throw Error(ErrorCode::io_error, fmt::format("{}: cannot write EXR: {}", path, e.what()));
  }
}

std::vector<ImageLayer> read_exr(const std::string& path) {
  const uint64_t file_bytes = regular_file_size(path, "EXR image");
  // OpenEXR rejects headers past these sizes while it reads them, before it allocates.
  static const bool limits_set = [] {
    Imf::Header::setMaxImageSize(max_image_side, max_image_side);
    Imf::Header::setMaxTileSize(4096, 4096);
    return true;
  }();
  (void)limits_set;
  std::vector<ImageLayer> layers;
  try {
    Imf::InputFile file(path.c_str());
    const Imath::Box2i dw = file.header().dataWindow();
    const int64_t w = int64_t(dw.max.x) - dw.min.x + 1, h = int64_t(dw.max.y) - dw.min.y + 1;
    if (w <= 0 || h <= 0 || w > max_image_side || h > max_image_side)
      throw Error(ErrorCode::parse_error, fmt::format("{}: bad EXR data window {}x{}", path, w, h));
    size_t channel_count = 0;
    for (auto it = file.header().channels().begin(); it != file.header().channels().end(); ++it)
      ++channel_count;
    check_decoded_size(path, uint64_t(w) * uint64_t(h) * channel_count * sizeof(float), file_bytes);
    std::map<std::string, size_t> layer_of;
    std::vector<std::vector<std::string>> full_names;
    for (auto it = file.header().channels().begin(); it != file.header().channels().end(); ++it) {
      const std::string full = it.name();
      const size_t dot = full.rfind('.');
      const std::string layer = dot == std::string::npos ? "color" : full.substr(0, dot);
      const std::string channel = dot == std::string::npos ? full : full.substr(dot + 1);
      auto [slot, fresh] = layer_of.try_emplace(layer, layers.size());
      if (fresh) {
        layers.push_back(ImageLayer{layer, {}, {}});
        full_names.emplace_back();
      }
      layers[slot->second].channel_names.push_back(channel);
      full_names[slot->second].push_back(full);
    }
    // EXR lists channels alphabetically; put R, G, B, A and X, Y, Z back in their order.
    auto rank = [](const std::string& c) {
      static const char* order[] = {"R", "G", "B", "A", "X", "Y", "Z"};
      for (int k = 0; k < 7; ++k)
        if (c == order[k]) return k < 4 ? k : k - 4;
      return 8;
    };
    for (size_t i = 0; i < layers.size(); ++i) {
      std::vector<size_t> idx(layers[i].channel_names.size());
      for (size_t k = 0; k < idx.size(); ++k) idx[k] = k;
      std::stable_sort(idx.begin(), idx.end(), [&](size_t a, size_t b) {
        return rank(layers[i].channel_names[a]) < rank(layers[i].channel_names[b]);
      });
      std::vector<std::string> names, fulls;
      for (size_t k : idx)
        names.push_back(layers[i].channel_names[k]), fulls.push_back(full_names[i][k]);
      layers[i].channel_names = names;
      full_names[i] = fulls;
    }
    Imf::FrameBuffer fb;
    for (size_t i = 0; i < layers.size(); ++i) {
      ImageLayer& l = layers[i];
      l.image = FloatImage(w, h, int(l.channel_names.size()));
      const size_t xs = sizeof(float) * size_t(l.image.channels);
      for (size_t c = 0; c < l.channel_names.size(); ++c) {
        char* base = (char*)(l.image.pixels.data() + c) - (ptrdiff_t(dw.min.x) * ptrdiff_t(xs)) -
                     ptrdiff_t(dw.min.y) * ptrdiff_t(xs) * w;
        fb.insert(full_names[i][c], Imf::Slice(Imf::FLOAT, base, xs, xs * size_t(w)));
      }
    }
    file.setFrameBuffer(fb);
    file.readPixels(dw.min.y, dw.max.y);
  } catch (const Error&) {
    throw;
  } catch (const std::exception& e) {
    throw Error(ErrorCode::parse_error, fmt::format("{}: cannot read EXR: {}", path, e.what()));
  }
  if (layers.empty())
    throw Error(ErrorCode::parse_error, fmt::format("{}: EXR has no channel", path));
  return layers;
}

FloatImage read_float_image(const std::string& path) {
  const std::string ext = lower_extension(path);
  if (ext == ".pfm") return read_pfm(path);
  if (ext == ".exr") {
    std::vector<ImageLayer> layers = read_exr(path);
    for (ImageLayer& l : layers)
      if (l.image.channels >= 3) {
        FloatImage rgb(l.image.width, l.image.height, 3);
        for (int y = 0; y < rgb.height; ++y)
          for (int x = 0; x < rgb.width; ++x)
            for (int c = 0; c < 3; ++c) rgb.at(x, y)[c] = l.image.at(x, y)[c];
        return rgb;
      }
    return std::move(layers[0].image);
  }
  return load_float_image_stb(path);
}

}  // namespace kestrel
