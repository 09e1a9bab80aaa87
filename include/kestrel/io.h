// kestrel public API: rays/hits interchange files and image output.
#pragma once
#include <cstdint>
#include <span>
#include <string>
#include <vector>

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

/// Writes 8-bit RGB pixels (rows top to bottom) as PNG.
void write_png(const std::string& path, int width, int height, std::span<const uint8_t> rgb);

}  // namespace kestrel
