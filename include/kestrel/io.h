// kestrel public API: rays/hits interchange files and image output.
#pragma once
#include <cstdint>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "kestrel/image.h"
#include "kestrel/trace.h"

namespace kestrel {

/// Reads a `.rays` file (DESIGN.md: "RAYS", version 1, count, 8 floats per ray).
std::vector<Ray> read_rays(const std::string& path);
/// Writes a `.rays` file.
void write_rays(const std::string& path, std::span<const Ray> rays);
/// Reads a `.hits` file ("HITS", version 1, count, (float t, uint32 prim_id) per hit).
std::vector<Hit> read_hits(const std::string& path);
/// Writes a `.hits` file; a miss is t = +inf, prim_id = 0xFFFFFFFF.
void write_hits(const std::string& path, std::span<const Hit> hits);

/// Writes a text file atomically (a temporary beside it, renamed into place once every write
/// succeeded; an existing file is kept on failure). Error(io_error) naming the file.
void write_text_file(const std::string& path, std::string_view text);

/// Writes 8-bit RGB pixels (rows top to bottom) as PNG.
void write_png(const std::string& path, int width, int height, std::span<const uint8_t> rgb);

}  // namespace kestrel

namespace kestrel {

/// One named layer of a multi-layer EXR: `channel_names` (one per channel) are appended to
/// the layer name with a dot ("albedo.R"); the layer named "" (or "color") writes bare
/// R, G, B so viewers show it as the image.
struct ImageLayer {
  std::string name;
  std::vector<std::string> channel_names;
  FloatImage image;
};

/// Writes every layer (same size) into one EXR file, 32-bit float, ZIP compressed.
void write_exr(const std::string& path, std::span<const ImageLayer> layers);
/// Reads an EXR file's channels grouped into layers by the part before the last dot
/// (bare R/G/B/A → the layer "color"); channels kept in file order within a layer.
std::vector<ImageLayer> read_exr(const std::string& path);

/// Writes a PFM (1 channel: "Pf", 3 channels: "PF"; 2 channels are padded with a zero
/// third channel), little-endian, rows bottom to top as the format says.
void write_pfm(const std::string& path, const FloatImage& image);
/// Reads a PFM ("PF" or "Pf", either byte order); rows returned top to bottom.
FloatImage read_pfm(const std::string& path);

/// Reads a float image for use as an environment or input: .pfm, .exr (its first layer
/// with 3 channels, else the first), .hdr (Radiance RGBE) or an 8-bit image (sRGB decoded).
FloatImage read_float_image(const std::string& path);

}  // namespace kestrel
