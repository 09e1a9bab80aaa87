// glTF 2.0 (.gltf / .glb) through tinygltf: the default scene's node hierarchy is flattened
// to world space (one TriangleMesh per node that has a mesh, primitives in order), with
// metallic-roughness materials and decoded textures. Accessors are bounds-checked against
// their buffers before use, so a truncated or inconsistent file is an Error, never a read
// past the end.
#include <fmt/format.h>
#include <tiny_gltf.h>

#include <array>
#include <cmath>
#include <filesystem>

#include "io/loaders.h"
#include "kestrel/error.h"

namespace kestrel {

namespace {

using Mat4 = std::array<double, 16>;  // column-major, as glTF stores it

Mat4 identity() { return {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1}; }

Mat4 mul(const Mat4& a, const Mat4& b) {
  Mat4 r{};
  for (int c = 0; c < 4; ++c)
    for (int rr = 0; rr < 4; ++rr) {
      double s = 0;
      for (int k = 0; k < 4; ++k) s += a[k * 4 + rr] * b[c * 4 + k];
      r[c * 4 + rr] = s;
    }
  return r;
}

Mat4 node_matrix(const tinygltf::Node& node) {
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
    const double x = node.rotation[0], y = node.rotation[1], z = node.rotation[2], w = node.rotation[3];
    r = {1 - 2 * (y * y + z * z), 2 * (x * y + z * w),     2 * (x * z - y * w),     0,
         2 * (x * y - z * w),     1 - 2 * (x * x + z * z), 2 * (y * z + x * w),     0,
         2 * (x * z + y * w),     2 * (y * z - x * w),     1 - 2 * (x * x + y * y), 0,
         0,                       0,                       0,                       1};
  }
  if (node.scale.size() == 3) {
    s[0] = node.scale[0];
    s[5] = node.scale[1];
    s[10] = node.scale[2];
  }
  return mul(t, mul(r, s));
}

Vec3 transform_point(const Mat4& m, Vec3 p) {
  return {float(m[0] * p.x + m[4] * p.y + m[8] * p.z + m[12]),
          float(m[1] * p.x + m[5] * p.y + m[9] * p.z + m[13]),
          float(m[2] * p.x + m[6] * p.y + m[10] * p.z + m[14])};
}

// Normals go through the inverse transpose; the cofactor matrix is proportional to it,
// and the result is renormalised anyway.
Vec3 transform_normal(const Mat4& m, Vec3 n) {
  const double a = m[0], b = m[4], c = m[8], d = m[1], e = m[5], f = m[9], g = m[2], h = m[6], i = m[10];
  const double cof[9] = {e * i - f * h, f * g - d * i, d * h - e * g, c * h - b * i, a * i - c * g,
                         b * g - a * h, b * f - c * e, c * d - a * f, a * e - b * d};
  double x = cof[0] * n.x + cof[3] * n.y + cof[6] * n.z;
  double y = cof[1] * n.x + cof[4] * n.y + cof[7] * n.z;
  double z = cof[2] * n.x + cof[5] * n.y + cof[8] * n.z;
  double len = std::sqrt(x * x + y * y + z * z);
  if (len > 0) x /= len, y /= len, z /= len;
  return {float(x), float(y), float(z)};
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
      fail(fmt::format("accessor {} has type {} x {}, expected {} components", accessor_index, acc.type,
                       acc.componentType, want_components));
    if (acc.sparse.isSparse) fail(fmt::format("accessor {}: sparse accessors are not supported", accessor_index));
    if (acc.bufferView < 0 || size_t(acc.bufferView) >= model.bufferViews.size())
      fail(fmt::format("accessor {} has no buffer view", accessor_index));
    const tinygltf::BufferView& bv = model.bufferViews[acc.bufferView];
    if (bv.buffer < 0 || size_t(bv.buffer) >= model.buffers.size())
      fail(fmt::format("buffer view {} names missing buffer {}", acc.bufferView, bv.buffer));
    const tinygltf::Buffer& buf = model.buffers[bv.buffer];
    const size_t element = size_t(components) * size_t(component_size);
    stride = bv.byteStride ? bv.byteStride : element;
    count = acc.count;
    const size_t begin = bv.byteOffset + acc.byteOffset;
    const size_t need = count ? begin + (count - 1) * stride + element : begin;
    if (bv.byteOffset + bv.byteLength > buf.data.size() || need > bv.byteOffset + bv.byteLength)
      fail(fmt::format("accessor {} reads past the end of buffer {} ({} bytes; file truncated?)", accessor_index,
                       bv.buffer, buf.data.size()));
    component_type = acc.componentType;
    return buf.data.data() + begin;
  }

  std::vector<Vec3> read_vec3(int accessor_index) const {
    size_t count, stride;
    int type;
    const unsigned char* p = view(accessor_index, 3, count, stride, type);
    if (type != TINYGLTF_COMPONENT_TYPE_FLOAT) fail(fmt::format("accessor {} must be float vec3", accessor_index));
    std::vector<Vec3> out(count);
    for (size_t i = 0; i < count; ++i) std::memcpy(&out[i], p + i * stride, sizeof(Vec3));
    return out;
  }

  std::vector<Vec2> read_vec2(int accessor_index) const {
    size_t count, stride;
    int type;
    const unsigned char* p = view(accessor_index, 2, count, stride, type);
    std::vector<Vec2> out(count);
    for (size_t i = 0; i < count; ++i) {
      const unsigned char* e = p + i * stride;
      if (type == TINYGLTF_COMPONENT_TYPE_FLOAT) {
        std::memcpy(&out[i], e, sizeof(Vec2));
      } else if (type == TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE) {
        out[i] = {e[0] / 255.0f, e[1] / 255.0f};
      } else if (type == TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT) {
        uint16_t v[2];
        std::memcpy(v, e, 4);
        out[i] = {v[0] / 65535.0f, v[1] / 65535.0f};
      } else {
        fail(fmt::format("accessor {}: unsupported texcoord component type {}", accessor_index, type));
      }
    }
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
        fail(fmt::format("accessor {}: index component type {} is not an unsigned integer", accessor_index, type));
      }
    }
    return out;
  }
};

Material convert_material(const tinygltf::Material& m, const tinygltf::Model& model) {
  Material out;
  out.name = m.name;
  const auto& pbr = m.pbrMetallicRoughness;
  if (pbr.baseColorFactor.size() >= 3)
    out.base_color = {float(pbr.baseColorFactor[0]), float(pbr.baseColorFactor[1]), float(pbr.baseColorFactor[2])};
  out.metallic = float(pbr.metallicFactor);
  out.roughness = float(pbr.roughnessFactor);
  float strength = 1.0f;
  auto ext = m.extensions.find("KHR_materials_emissive_strength");
  if (ext != m.extensions.end() && ext->second.Has("emissiveStrength"))
    strength = float(ext->second.Get("emissiveStrength").GetNumberAsDouble());
  if (m.emissiveFactor.size() == 3)
    out.emission = {float(m.emissiveFactor[0]) * strength, float(m.emissiveFactor[1]) * strength,
                    float(m.emissiveFactor[2]) * strength};
  auto texture = [&](int index) { return index >= 0 && size_t(index) < model.textures.size() ? index : -1; };
  out.base_color_texture = texture(pbr.baseColorTexture.index);
  out.metallic_roughness_texture = texture(pbr.metallicRoughnessTexture.index);
  out.emission_texture = texture(m.emissiveTexture.index);
  out.normal_texture = texture(m.normalTexture.index);
  return out;
}

Texture convert_texture(const tinygltf::Texture& t, const tinygltf::Model& model) {
  Texture out;
  out.name = t.name;
  if (t.source < 0 || size_t(t.source) >= model.images.size()) return out;
  const tinygltf::Image& img = model.images[t.source];
  if (out.name.empty()) out.name = img.name.empty() ? img.uri : img.name;
  if (img.bits != 8 || img.component < 1 || img.component > 4 || img.width <= 0 || img.height <= 0 ||
      img.image.size() < size_t(img.width) * img.height * img.component)
    return out;
  out.width = img.width;
  out.height = img.height;
  out.rgba.resize(size_t(img.width) * img.height * 4);
  for (size_t i = 0; i < size_t(img.width) * img.height; ++i) {
    const unsigned char* s = &img.image[i * img.component];
    unsigned char* d = &out.rgba[i * 4];
    d[0] = s[0];
    d[1] = img.component >= 3 ? s[1] : s[0];
    d[2] = img.component >= 3 ? s[2] : s[0];
    d[3] = img.component == 4 ? s[3] : (img.component == 2 ? s[1] : 255);
  }
  return out;
}

}  // namespace

Scene load_gltf(const std::string& path) {
  require_readable_file(path);
  tinygltf::TinyGLTF loader;
  tinygltf::Model model;
  std::string err, warn;
  const bool binary = std::filesystem::path(path).extension() == ".glb";
  const bool ok = binary ? loader.LoadBinaryFromFile(&model, &err, &warn, path)
                         : loader.LoadASCIIFromFile(&model, &err, &warn, path);
  if (!ok) {
    while (!err.empty() && (err.back() == '\n' || err.back() == '\r')) err.pop_back();
    throw Error(ErrorCode::parse_error, fmt::format("{}: {}", path, err.empty() ? "not a valid glTF file" : err));
  }
  GltfReader reader{path, model};
  Scene scene;
  scene.source = path;
  for (const auto& m : model.materials) scene.materials.push_back(convert_material(m, model));
  for (const auto& t : model.textures) scene.textures.push_back(convert_texture(t, model));
  const uint32_t default_material = uint32_t(scene.materials.size());
  scene.materials.push_back(Material{.name = "default"});

  const int scene_index = model.defaultScene >= 0 ? model.defaultScene : 0;
  std::vector<int> roots;
  if (size_t(scene_index) < model.scenes.size()) {
    roots = model.scenes[scene_index].nodes;
  } else {
    for (size_t i = 0; i < model.nodes.size(); ++i) roots.push_back(int(i));  // no scene: every node
  }
  // Depth-first over the hierarchy; the depth cap rejects cycles in malformed files.
  auto visit = [&](auto&& self, int node_index, const Mat4& parent, int depth) -> void {
    if (node_index < 0 || size_t(node_index) >= model.nodes.size())
      reader.fail(fmt::format("node {} does not exist", node_index));
    if (depth > 256) reader.fail(fmt::format("node {}: hierarchy deeper than 256 (cycle?)", node_index));
    const tinygltf::Node& node = model.nodes[node_index];
    const Mat4 world = mul(parent, node_matrix(node));
    if (node.mesh >= 0) {
      if (size_t(node.mesh) >= model.meshes.size()) reader.fail(fmt::format("node {} names missing mesh {}", node_index, node.mesh));
      const tinygltf::Mesh& gm = model.meshes[node.mesh];
      TriangleMesh mesh;
      mesh.name = gm.name.empty() ? fmt::format("mesh{}", node.mesh) : gm.name;
      bool all_normals = true, all_uvs = true;
      for (const tinygltf::Primitive& prim : gm.primitives) {
        if (prim.mode != TINYGLTF_MODE_TRIANGLES && prim.mode != -1) continue;  // points/lines/strips skipped
        auto pos_it = prim.attributes.find("POSITION");
        if (pos_it == prim.attributes.end()) continue;
        std::vector<Vec3> positions = reader.read_vec3(pos_it->second);
        std::vector<uint32_t> indices;
        if (prim.indices >= 0) {
          indices = reader.read_indices(prim.indices);
        } else {
          indices.resize(positions.size());
          for (size_t i = 0; i < indices.size(); ++i) indices[i] = uint32_t(i);
        }
        std::vector<Vec3> normals;
        std::vector<Vec2> uvs;
        if (auto it = prim.attributes.find("NORMAL"); it != prim.attributes.end()) normals = reader.read_vec3(it->second);
        if (auto it = prim.attributes.find("TEXCOORD_0"); it != prim.attributes.end()) uvs = reader.read_vec2(it->second);
        all_normals &= normals.size() == positions.size();
        all_uvs &= uvs.size() == positions.size();
        const uint32_t base = uint32_t(mesh.positions.size());
        for (Vec3 p : positions) mesh.positions.push_back(transform_point(world, p));
        if (all_normals) for (Vec3 n : normals) mesh.normals.push_back(transform_normal(world, n));
        if (all_uvs) mesh.uvs.insert(mesh.uvs.end(), uvs.begin(), uvs.end());
        const uint32_t material = prim.material >= 0 && size_t(prim.material) < model.materials.size()
                                      ? uint32_t(prim.material)
                                      : default_material;
        // Out-of-range indices stay out of range after the offset (validation counts them).
        for (size_t i = 0; i + 2 < indices.size(); i += 3) {
          for (int k = 0; k < 3; ++k)
            mesh.indices.push_back(indices[i + k] < positions.size() ? base + indices[i + k] : 0xFFFFFFFFu);
          mesh.material_ids.push_back(material);
        }
      }
      if (!all_normals) mesh.normals.clear();
      if (!all_uvs) mesh.uvs.clear();
      scene.meshes.push_back(std::move(mesh));
    }
    for (int child : node.children) self(self, child, world, depth + 1);
  };
  for (int root : roots) visit(visit, root, identity(), 0);
  return scene;
}

}  // namespace kestrel
