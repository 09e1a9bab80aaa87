// Scene file loaders behind load_scene().
#pragma once
#include <string>

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

/// Decodes a PNG/JPEG/... image to RGBA8; Error naming the file when it cannot.
Texture load_texture(const std::string& path);

/// Decodes a Radiance .hdr (linear) or an 8-bit image (sRGB decoded) to float RGB.
FloatImage load_float_image_stb(const std::string& path);

/// Throws Error(file_not_found) unless `path` names a readable regular file.
void require_readable_file(const std::string& path);

}  // namespace kestrel
