// Scene file loaders behind load_scene().
#pragma once
#include <cstdint>
#include <string>
#include <vector>

#include "kestrel/io.h"
#include "kestrel/scene.h"

namespace kestrel {

/// Wavefront OBJ + MTL (tinyobjloader). Triangles numbered in `f` order, k-gons fanned.
Scene load_obj(const std::string& path);
/// glTF 2.0, .gltf or .glb (tinygltf): the default scene's node hierarchy flattened to
/// world space, one mesh per (node, mesh), primitives in order.
Scene load_gltf(const std::string& path);
/// Built-in scenes by name ("cornell_box").
Scene make_builtin_scene(const std::string& name);
/// The warning for triangles validation skipped ("" when none was): counts by reason.
std::string skipped_triangles_warning(const std::string& source, const ValidationReport& r);

/// Decodes a PNG/JPEG/... image to RGBA8; Error naming the file when it cannot.
Texture load_texture(const std::string& path);

/// Decodes an encoded image (PNG, JPEG, ...) in memory to RGBA8 after checking its size;
/// false with `problem` set when it cannot.
bool decode_rgba8(const unsigned char* bytes, size_t size, int& width, int& height,
                  std::vector<unsigned char>& rgba, std::string& problem);

/// Decodes a Radiance .hdr (linear) or an 8-bit image (sRGB decoded) to float RGB.
FloatImage load_float_image_stb(const std::string& path);

/// Throws Error(file_not_found) unless `path` names a readable regular file.
void require_readable_file(const std::string& path);

/// Largest width or height of an image kestrel reads.
inline constexpr int max_image_side = 32768;
/// Throws Error(parse_error) naming the file when an image would decode to more bytes than a
/// file of file_bytes can honestly hold (max(64 MiB, 1100 x the file): deflate's ceiling).
void check_decoded_size(const std::string& path, uint64_t decoded_bytes, uint64_t file_bytes);

}  // namespace kestrel
