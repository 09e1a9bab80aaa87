// glTF 2.0 reading shared by the flattening loader (gltf_loader.cpp) and the instanced,
// animated import (scene/gltf_animation.cpp): the model, node matrices, and accessors
// bounds-checked against their buffers.
#pragma once
#include <fmt/format.h>
#include <tiny_gltf.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <optional>
#include <string>
#include <vector>

#include "core/file_io.h"
#include "kestrel/error.h"
#include "kestrel/scene.h"
#include "kestrel/types.h"

namespace kestrel::gltf {

/// Loads a .gltf or .glb file (by its extension, any case); Error naming the file when it is
/// not valid glTF or its node graph is not a tree (check_node_tree).
tinygltf::Model load_model(const std::string& path);
/// Error naming the file unless the nodes form a forest: children exist, one parent each,
/// no cycles, scene roots without parents and listed once.
void check_node_tree(const std::string& path, const tinygltf::Model& model);
/// A glTF material / texture as kestrel's (gltf_loader.cpp).
Material convert_material(const tinygltf::Material& m, const tinygltf::Model& model);
Texture convert_texture(const tinygltf::Texture& t, const tinygltf::Model& model);

using Mat4 = std::array<double, 16>;  // column-major, as glTF stores it

inline Mat4 identity() {
  return {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1};
}

inline Mat4 mul(const Mat4& a, const Mat4& b) {
  Mat4 r{};
  for (int c = 0; c < 4; ++c)
    for (int rr = 0; rr < 4; ++rr) {
      double s = 0;
      for (int k = 0; k < 4; ++k) s += a[k * 4 + rr] * b[c * 4 + k];
      r[c * 4 + rr] = s;
    }
  return r;
}

inline Mat4 node_matrix(const tinygltf::Node& node) {
  if (node.matrix.size() == 16) {
    Mat4 m;
    for (int i = 0; i < 16; ++i) m[i] = node.matrix[i];
    return m;
  }
  Mat4 t = identity(), r = identity(), s = identity();
  if (node.translation.size() == 3) {
    t[12] = node.translation[0];
    t[13] = node.translation[1];
    t[14] = node.translation[2];
  }
  if (node.rotation.size() == 4) {
    const double x = node.rotation[0], y = node.rotation[1], z = node.rotation[2],
                 w = node.rotation[3];
    r = {1 - 2 * (y * y + z * z),
         2 * (x * y + z * w),
         2 * (x * z - y * w),
         0,
         2 * (x * y - z * w),
         1 - 2 * (x * x + z * z),
         2 * (y * z + x * w),
         0,
         2 * (x * z + y * w),
         2 * (y * z - x * w),
         1 - 2 * (x * x + y * y),
         0,
         0,
         0,
         0,
         1};
  }
  if (node.scale.size() == 3) {
    s[0] = node.scale[0];
    s[5] = node.scale[1];
    s[10] = node.scale[2];
  }
  return mul(t, mul(r, s));
}

inline Vec3 transform_point(const Mat4& m, Vec3 p) {
  return {float(m[0] * p.x + m[4] * p.y + m[8] * p.z + m[12]),
          float(m[1] * p.x + m[5] * p.y + m[9] * p.z + m[13]),
          float(m[2] * p.x + m[6] * p.y + m[10] * p.z + m[14])};
}

// Normals go through the inverse transpose; the cofactor matrix is proportional to it,
// and the result is renormalised anyway.
inline Vec3 transform_normal(const Mat4& m, Vec3 n) {
  const double a = m[0], b = m[4], c = m[8], d = m[1], e = m[5], f = m[9], g = m[2], h = m[6],
               i = m[10];
  const double cof[9] = {e * i - f * h, f * g - d * i, d * h - e * g, c * h - b * i, a * i - c * g,
                         b * g - a * h, b * f - c * e, c * d - a * f, a * e - b * d};
  double x = cof[0] * n.x + cof[3] * n.y + cof[6] * n.z;
  double y = cof[1] * n.x + cof[4] * n.y + cof[7] * n.z;
  double z = cof[2] * n.x + cof[5] * n.y + cof[8] * n.z;
  double len = std::sqrt(x * x + y * y + z * z);
  if (len > 0) x /= len, y /= len, z /= len;
  return {float(x), float(y), float(z)};
}

/// Places a light by a node's world matrix: position = its origin, direction = its -Z axis.
/// False (direction untouched) when the matrix collapses that axis.
inline bool place_light(Light& l, const Mat4& world) {
  l.position = transform_point(world, {0, 0, 0});
  const Vec3 z = transform_point(world, {0, 0, -1});
  const Vec3 d{z.x - l.position.x, z.y - l.position.y, z.z - l.position.z};
  const float len = std::sqrt(d.x * d.x + d.y * d.y + d.z * d.z);
  if (!(len > 0 && std::isfinite(len))) return false;
  l.direction = {d.x / len, d.y / len, d.z / len};
  return true;
}

/// The KHR_lights_punctual light a node carries, placed by the node's world matrix (position
/// = its origin, direction = its -Z axis), or nullopt. Throws Error naming the file, the node
/// and the light for a missing light, an unknown type or a light_problem().
std::optional<Light> node_light(const std::string& path, const tinygltf::Model& model,
                                int node_index, const Mat4& world);

// Appends a primitive's per-vertex values (texture coordinates, colours) to a mesh's whose
// first `before` vertices came from earlier primitives: a primitive without them gets `fill`
// once another has them (so one primitive without coordinates no longer strips the textures
// of the mesh's others), and the earlier ones are filled the same way when the first
// primitive with them comes.
template <class T>
void add_per_vertex(std::vector<T>& mesh_values, size_t before, const std::vector<T>& values,
                    size_t count, T fill) {
  if (values.empty() && mesh_values.empty()) return;
  mesh_values.resize(before, fill);
  if (values.empty())
    mesh_values.resize(before + count, fill);
  else
    mesh_values.insert(mesh_values.end(), values.begin(), values.end());
}

struct GltfReader {
  const std::string& path;
  const tinygltf::Model& model;

  [[noreturn]] void fail(const std::string& what) const {
    throw Error(ErrorCode::parse_error, fmt::format("{}: {}", path, what));
  }

  // Returns a pointer to element 0 and the byte stride, after checking every element fits.
  const unsigned char* view(int accessor_index, int want_components, size_t& count, size_t& stride,
                            int& component_type) const {
    if (accessor_index < 0 || size_t(accessor_index) >= model.accessors.size())
      fail(fmt::format("accessor {} does not exist", accessor_index));
    const tinygltf::Accessor& acc = model.accessors[accessor_index];
    const int components = tinygltf::GetNumComponentsInType(uint32_t(acc.type));
    const int component_size = tinygltf::GetComponentSizeInBytes(uint32_t(acc.componentType));
    if (components != want_components || component_size <= 0)
      fail(fmt::format("accessor {} has type {} x {}, expected {} components", accessor_index,
                       acc.type, acc.componentType, want_components));
    if (acc.sparse.isSparse)
      fail(fmt::format("accessor {}: sparse accessors are not supported", accessor_index));
    if (acc.bufferView < 0 || size_t(acc.bufferView) >= model.bufferViews.size())
      fail(fmt::format("accessor {} has no buffer view", accessor_index));
    const tinygltf::BufferView& bv = model.bufferViews[acc.bufferView];
    if (bv.buffer < 0 || size_t(bv.buffer) >= model.buffers.size())
      fail(fmt::format("buffer view {} names missing buffer {}", acc.bufferView, bv.buffer));
    const tinygltf::Buffer& buf = model.buffers[bv.buffer];
    const size_t element = size_t(components) * size_t(component_size);
    stride = bv.byteStride ? bv.byteStride : element;
    count = acc.count;
    // Every sum and product checked: offsets and counts near 2^64 must not wrap past the test.
    uint64_t view_end = 0, begin = 0, span = 0, need = 0;
    const bool fits =
        add_fits(bv.byteOffset, bv.byteLength, view_end) &&
        add_fits(bv.byteOffset, acc.byteOffset, begin) &&
        (count == 0 || (mul_fits(count - 1, stride, span) && add_fits(span, element, span))) &&
        add_fits(begin, count ? span : 0, need);
    if (!fits || view_end > buf.data.size() || need > view_end)
      fail(fmt::format(
          "accessor {} ({} elements at byte {} of buffer view {}) reads past the end of buffer {} "
          "({} bytes; "
          "file truncated?)",
          accessor_index, count, acc.byteOffset, acc.bufferView, bv.buffer, buf.data.size()));
    component_type = acc.componentType;
    return buf.data.data() + begin;
  }

  // An accessor of `components` per element (SCALAR, VEC3, VEC4...) as floats, flat: float
  // components as they are, integer ones (core glTF's texture coordinates, colours and
  // animation outputs; KHR_mesh_quantization's positions, normals, texture coordinates and
  // morph deltas) as their value, or normalised where the accessor says so (unsigned c / max,
  // signed max(c / max, -1)).
  std::vector<float> read_floats(int accessor_index, int components) const {
    size_t count, stride;
    int type;
    const unsigned char* p = view(accessor_index, components, count, stride, type);
    const bool normalized = model.accessors[size_t(accessor_index)].normalized;
    size_t size = 4;
    float scale = 1;
    switch (type) {
      case TINYGLTF_COMPONENT_TYPE_FLOAT:
        break;
      case TINYGLTF_COMPONENT_TYPE_BYTE:
        size = 1, scale = 127;
        break;
      case TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE:
        size = 1, scale = 255;
        break;
      case TINYGLTF_COMPONENT_TYPE_SHORT:
        size = 2, scale = 32767;
        break;
      case TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT:
        size = 2, scale = 65535;
        break;
      default:
        fail(fmt::format("accessor {}: component type {} is not a float, byte or short",
                         accessor_index, type));
    }
    std::vector<float> out(count * size_t(components));  // view() bounded count by the buffer
    for (size_t i = 0; i < count; ++i)
      for (int k = 0; k < components; ++k) {
        const unsigned char* e = p + i * stride + size_t(k) * size;
        float v;
        if (type == TINYGLTF_COMPONENT_TYPE_FLOAT) {
          std::memcpy(&v, e, 4);
        } else if (type == TINYGLTF_COMPONENT_TYPE_BYTE) {
          v = float(int8_t(e[0]));
        } else if (type == TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE) {
          v = float(e[0]);
        } else if (type == TINYGLTF_COMPONENT_TYPE_SHORT) {
          int16_t c;
          std::memcpy(&c, e, 2);
          v = float(c);
        } else {
          uint16_t c;
          std::memcpy(&c, e, 2);
          v = float(c);
        }
        if (normalized && type != TINYGLTF_COMPONENT_TYPE_FLOAT) v = std::max(v / scale, -1.0f);
        out[i * size_t(components) + size_t(k)] = v;
      }
    return out;
  }

  // A triangle-list primitive's positions and indices (0, 1, 2, ... when it has none);
  // false for points / lines / strips and primitives without positions (skipped).
  bool read_triangles(const tinygltf::Primitive& prim, std::vector<Vec3>& positions,
                      std::vector<uint32_t>& indices) const {
    if (prim.mode != TINYGLTF_MODE_TRIANGLES && prim.mode != -1) return false;
    auto pos = prim.attributes.find("POSITION");
    if (pos == prim.attributes.end()) return false;
    positions = read_vec3(pos->second);
    if (prim.indices >= 0) {
      indices = read_indices(prim.indices);
    } else {
      indices.resize(positions.size());
      for (size_t i = 0; i < indices.size(); ++i) indices[i] = uint32_t(i);
    }
    return true;
  }

  // A primitive's NORMAL and TEXCOORD_0, each left empty unless it has one per vertex.
  void read_normals_uvs(const tinygltf::Primitive& prim, size_t vertex_count,
                        std::vector<Vec3>& normals, std::vector<Vec2>& uvs) const {
    normals.clear(), uvs.clear();
    if (auto it = prim.attributes.find("NORMAL"); it != prim.attributes.end())
      normals = read_vec3(it->second);
    const tinygltf::Material* m =
        prim.material >= 0 && size_t(prim.material) < model.materials.size()
            ? &model.materials[size_t(prim.material)]
            : nullptr;
    const std::string set = fmt::format("TEXCOORD_{}", m ? texcoord_set(*m) : 0);
    if (auto it = prim.attributes.find(set); it != prim.attributes.end())
      uvs = read_vec2(it->second);
    if (normals.size() != vertex_count) normals.clear();
    if (uvs.size() != vertex_count) uvs.clear();
    if (m) apply_texture_transform(*m, uvs);
  }

  // A primitive's COLOR_0 (VEC3 or VEC4, its alpha not read; floats or normalised unsigned
  // bytes or shorts) clamped to [0, 1] (NaN as 0); empty unless it has one per vertex.
  std::vector<Vec3> read_colors(const tinygltf::Primitive& prim, size_t vertex_count) const {
    const auto it = prim.attributes.find("COLOR_0");
    if (it == prim.attributes.end()) return {};
    const int index = it->second;
    const int components =
        index >= 0 && size_t(index) < model.accessors.size() &&
                tinygltf::GetNumComponentsInType(uint32_t(model.accessors[size_t(index)].type)) == 4
            ? 4
            : 3;  // (view() names a missing accessor or another type)
    const std::vector<float> f = read_floats(index, components);
    std::vector<Vec3> out(f.size() / size_t(components));
    for (size_t i = 0; i < out.size(); ++i)
      for (int k = 0; k < 3; ++k) {
        const float v = f[i * size_t(components) + size_t(k)];
        out[i][k] = v >= 0 ? std::min(v, 1.0f) : 0.0f;
      }
    if (out.size() != vertex_count) out.clear();
    return out;
  }

  // A material's texture slots in the order kestrel takes their coordinates from (base colour,
  // emissive, metallic-roughness, normal): each one's texCoord (-1 without a texture) and its
  // textureInfo's extensions.
  struct TextureSlot {
    int set;
    const tinygltf::ExtensionMap* extensions;
  };
  static std::array<TextureSlot, 4> texture_slots(const tinygltf::Material& m) {
    auto slot = [](const auto& info) {
      return TextureSlot{info.index >= 0 ? info.texCoord : -1, &info.extensions};
    };
    return {slot(m.pbrMetallicRoughness.baseColorTexture), slot(m.emissiveTexture),
            slot(m.pbrMetallicRoughness.metallicRoughnessTexture), slot(m.normalTexture)};
  }

  // The texture coordinate set a material's maps read (kestrel's materials have one): the base
  // colour texture's texCoord (or its KHR_texture_transform's), else the emissive,
  // metallic-roughness or normal texture's, whichever the material has first; 0 without one.
  static int texcoord_set(const tinygltf::Material& m) {
    const std::array<TextureSlot, 4> maps = texture_slots(m);
    for (const auto& [set, ext] : maps) {
      if (set < 0) continue;  // no texture in this slot
      if (const auto it = ext->find("KHR_texture_transform");
          it != ext->end() && it->second.Has("texCoord") && it->second.Get("texCoord").IsInt())
        return std::clamp(it->second.Get("texCoord").GetNumberAsInt(), 0, 7);
      return std::clamp(set, 0, 7);
    }
    return 0;
  }

  // KHR_texture_transform, applied to the texture coordinates themselves (kestrel's materials
  // have one set of coordinates for all their maps): the transform of the base colour texture,
  // else of the emissive, metallic-roughness or normal texture, whichever has one first. The
  // extension's matrix: uv' = offset + R(rotation) (scale * uv), with R = [cos -sin; sin cos].
  void apply_texture_transform(const tinygltf::Material& m, std::vector<Vec2>& uvs) const {
    for (const auto& [set, ext] : texture_slots(m)) {
      const auto it = ext->find("KHR_texture_transform");
      if (it == ext->end() || !it->second.IsObject()) continue;
      const tinygltf::Value& v = it->second;
      auto number = [&](const tinygltf::Value& x, double fallback) {
        return x.IsNumber() ? x.GetNumberAsDouble() : fallback;
      };
      auto pair = [&](const char* key, double fallback, double out[2]) {
        out[0] = out[1] = fallback;
        if (!v.Has(key) || !v.Get(key).IsArray() || v.Get(key).ArrayLen() < 2) return;
        out[0] = number(v.Get(key).Get(0), fallback), out[1] = number(v.Get(key).Get(1), fallback);
      };
      double offset[2], scale[2];
      pair("offset", 0.0, offset);
      pair("scale", 1.0, scale);
      const double r = v.Has("rotation") ? number(v.Get("rotation"), 0.0) : 0.0;
      const double c = std::cos(r), s = std::sin(r);
      for (Vec2& uv : uvs) {
        const double x = scale[0] * uv.x, y = scale[1] * uv.y;
        uv = {float(offset[0] + c * x - s * y), float(offset[1] + s * x + c * y)};
      }
      return;
    }
  }

  std::vector<Vec3> read_vec3(int accessor_index) const {
    const std::vector<float> f = read_floats(accessor_index, 3);
    std::vector<Vec3> out(f.size() / 3);
    std::memcpy(static_cast<void*>(out.data()), f.data(), f.size() * sizeof(float));
    return out;
  }

  std::vector<Vec2> read_vec2(int accessor_index) const {
    const std::vector<float> f = read_floats(accessor_index, 2);
    std::vector<Vec2> out(f.size() / 2);
    std::memcpy(static_cast<void*>(out.data()), f.data(), f.size() * sizeof(float));
    return out;
  }

  std::vector<uint32_t> read_indices(int accessor_index) const {
    size_t count, stride;
    int type;
    const unsigned char* p = view(accessor_index, 1, count, stride, type);
    std::vector<uint32_t> out(count);
    for (size_t i = 0; i < count; ++i) {
      const unsigned char* e = p + i * stride;
      if (type == TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE) {
        out[i] = e[0];
      } else if (type == TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT) {
        uint16_t v;
        std::memcpy(&v, e, 2);
        out[i] = v;
      } else if (type == TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT) {
        std::memcpy(&out[i], e, 4);
      } else {
        fail(fmt::format("accessor {}: index component type {} is not an unsigned integer",
                         accessor_index, type));
      }
    }
    return out;
  }
};

}  // namespace kestrel::gltf
