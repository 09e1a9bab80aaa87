// Wavefront OBJ + MTL through tinyobjloader.
//
// tinyobjloader parses leniently (a bad number reads as 0, a short face is dropped), which
// would silently renumber triangles, so a light line check runs first and reports the file
// and line of the first malformed `v` or `f` record. Faces are fan-triangulated here, not by
// the library, so prim ids follow DESIGN.md: triangles in `f` order, k-gons as (v0,v1,v2),
// (v0,v2,v3), ... Out-of-range indices are kept (validation counts and skips them).
#include <fmt/format.h>
#include <tiny_obj_loader.h>

#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <map>
#include <sstream>
#include <unordered_map>

#include "io/loaders.h"
#include "kestrel/error.h"

namespace kestrel {

namespace {

[[noreturn]] void malformed(const std::string& path, size_t line, const std::string& what) {
  throw Error(ErrorCode::parse_error, fmt::format("{}:{}: {}", path, line, what));
}

bool parse_float(const char*& p, const char* end, float& v) {
  while (p < end && (*p == ' ' || *p == '\t')) ++p;
  if (p >= end) return false;
  auto [next, ec] = std::from_chars(p, end, v);
  if (ec != std::errc() && ec != std::errc::result_out_of_range) return false;
  if (next < end && !(*next == ' ' || *next == '\t' || *next == '\r')) return false;
  p = next;
  return true;
}

// Checks `v x y z [w]` and `f a b c ...` (each a, a/b, a//c or a/b/c, non-zero integers).
// Returns the (0-based) ids of vertices with a NaN or Inf coordinate: tinyobjloader reads
// those as 0, which would turn a corrupt vertex into a plausible one.
std::vector<size_t> check_obj_lines(const std::string& path, const std::string& text) {
  std::vector<size_t> nonfinite;
  size_t vertex_id = 0;
  size_t line = 0;
  const char* p = text.data();
  const char* const end = p + text.size();
  while (p < end) {
    ++line;
    const char* eol = static_cast<const char*>(std::memchr(p, '\n', size_t(end - p)));
    if (!eol) eol = end;
    const char* q = p;
    while (q < eol && (*q == ' ' || *q == '\t')) ++q;
    if (q + 1 < eol && q[0] == 'v' && (q[1] == ' ' || q[1] == '\t')) {
      q += 1;
      bool finite = true;
      for (int k = 0; k < 3; ++k) {
        float value;
        if (!parse_float(q, eol, value)) malformed(path, line, "vertex needs three numbers");
        finite &= std::isfinite(value);
      }
      if (!finite) nonfinite.push_back(vertex_id);
      ++vertex_id;
    } else if (q + 1 < eol && q[0] == 'f' && (q[1] == ' ' || q[1] == '\t')) {
      q += 1;
      int corners = 0;
      while (true) {
        while (q < eol && (*q == ' ' || *q == '\t' || *q == '\r')) ++q;
        if (q >= eol) break;
        for (int part = 0; part < 3 && q < eol && *q != ' ' && *q != '\t' && *q != '\r'; ++part) {
          if (*q == '/' && part > 0) {  // empty texcoord slot in a//c
            ++q;
            continue;
          }
          long long v = 0;
          auto [next, ec] = std::from_chars(q, eol, v);
          if (ec != std::errc() || v == 0) malformed(path, line, "face index must be a non-zero integer");
          q = next;
          if (q < eol && *q == '/') ++q;
          else break;
        }
        if (q < eol && *q != ' ' && *q != '\t' && *q != '\r') malformed(path, line, "malformed face corner");
        ++corners;
      }
      if (corners < 3) malformed(path, line, fmt::format("face has {} corners, needs at least 3", corners));
    }
    p = eol + 1;
  }
  return nonfinite;
}

struct CornerKey {
  int v, vt, vn;
  bool operator==(const CornerKey&) const = default;
};
struct CornerHash {
  size_t operator()(const CornerKey& k) const {
    uint64_t h = uint64_t(uint32_t(k.v)) * 0x9E3779B97F4A7C15ull;
    h ^= (uint64_t(uint32_t(k.vt)) + 0x632BE59BD9B4E019ull + (h << 6) + (h >> 2));
    h ^= (uint64_t(uint32_t(k.vn)) + 0x8CB92BA72F3D8DD7ull + (h << 6) + (h >> 2));
    return size_t(h);
  }
};

Material convert_material(const tinyobj::material_t& m) {
  Material out;
  out.name = m.name;
  out.base_color = {m.diffuse[0], m.diffuse[1], m.diffuse[2]};
  out.emission = {m.emission[0], m.emission[1], m.emission[2]};
  out.specular = std::clamp(std::max({m.specular[0], m.specular[1], m.specular[2]}), 0.0f, 1.0f);
  // The PBR extension (Pr/Pm) when given; otherwise roughness from the Phong exponent.
  if (m.roughness > 0.0f || m.metallic > 0.0f) {
    out.roughness = m.roughness;
    out.metallic = m.metallic;
  } else if (m.shininess > 0.0f) {
    out.roughness = std::clamp(std::sqrt(2.0f / (m.shininess + 2.0f)), 0.0f, 1.0f);
  }
  return out;
}

}  // namespace

Scene load_obj(const std::string& path) {
  require_readable_file(path);
  std::string text;
  {
    std::ifstream f(path, std::ios::binary);
    text.assign(std::istreambuf_iterator<char>(f), std::istreambuf_iterator<char>());
  }
  const std::vector<size_t> nonfinite_vertices = check_obj_lines(path, text);

  // The MTL files named by `mtllib` are read here and handed over as text, so a missing
  // .mtl is not fatal (its materials fall back to the default).
  const std::filesystem::path dir = std::filesystem::path(path).parent_path();
  std::string mtl_text;
  {
    std::istringstream obj_stream(text);
    std::string line_text;
    while (std::getline(obj_stream, line_text)) {
      if (line_text.rfind("mtllib", 0) != 0) continue;
      std::string name = line_text.substr(6);
      name.erase(0, name.find_first_not_of(" \t"));
      while (!name.empty() && (name.back() == '\r' || name.back() == ' ')) name.pop_back();
      std::ifstream mtl(dir / name, std::ios::binary);
      if (mtl) mtl_text.append(std::istreambuf_iterator<char>(mtl), std::istreambuf_iterator<char>()).append("\n");
    }
  }
  tinyobj::ObjReaderConfig config;
  config.triangulate = false;
  config.vertex_color = false;
  tinyobj::ObjReader reader;
  if (!reader.ParseFromString(text, mtl_text, config) && !reader.Error().empty())
    throw Error(ErrorCode::parse_error, fmt::format("{}: {}", path, reader.Error()));
  const std::vector<tinyobj::material_t>& materials = reader.GetMaterials();
  const tinyobj::attrib_t& attrib = reader.GetAttrib();
  // Restore NaN for vertices whose text was not finite (a copy only when there are some).
  std::vector<float> patched;
  if (!nonfinite_vertices.empty()) {
    patched = attrib.vertices;
    for (size_t v : nonfinite_vertices)
      if (3 * v + 2 < patched.size()) patched[3 * v] = std::numeric_limits<float>::quiet_NaN();
  }
  const std::vector<float>& vertices = nonfinite_vertices.empty() ? attrib.vertices : patched;
  Scene scene;
  scene.source = path;
  // Texture maps named by the MTL (map_Kd, map_Ke), each file decoded once. A missing or
  // undecodable image leaves the material untextured and a warning naming the file and the
  // problem in Scene::warnings; it does not fail the scene.
  std::map<std::string, int> texture_of;
  auto texture = [&](const std::string& name) -> int {
    if (name.empty()) return -1;
    auto [it, fresh] = texture_of.try_emplace(name, -1);
    if (fresh) {
      try {
        scene.textures.push_back(load_texture((dir / name).string()));
        it->second = int(scene.textures.size() - 1);
      } catch (const Error& e) {
        scene.warnings.push_back(fmt::format("{}: texture '{}' not used: {}", path, name, e.what()));
      }
    }
    return it->second;
  };
  for (const auto& m : materials) {
    Material material = convert_material(m);
    material.base_color_texture = texture(m.diffuse_texname);
    material.emission_texture = texture(m.emissive_texname);
    scene.materials.push_back(material);
  }
  const uint32_t default_material = uint32_t(scene.materials.size());
  scene.materials.push_back(Material{.name = "default"});

  TriangleMesh mesh;
  mesh.name = std::filesystem::path(path).stem().string();
  const size_t vertex_count = vertices.size() / 3;
  const bool has_extra = !attrib.normals.empty() || !attrib.texcoords.empty();
  std::unordered_map<CornerKey, uint32_t, CornerHash> corner_of;
  if (!has_extra) {
    mesh.positions.resize(vertex_count);
    for (size_t i = 0; i < vertex_count; ++i)
      mesh.positions[i] = {vertices[3 * i], vertices[3 * i + 1], vertices[3 * i + 2]};
  }
  // Out-of-range corners map to an index past the vertex array: validation counts them.
  const uint32_t bad_index = 0xFFFFFFFFu;
  auto corner_index = [&](const tinyobj::index_t& c) -> uint32_t {
    if (c.vertex_index < 0 || size_t(c.vertex_index) >= vertex_count) return bad_index;
    if (!has_extra) return uint32_t(c.vertex_index);
    auto [it, fresh] = corner_of.try_emplace(CornerKey{c.vertex_index, c.texcoord_index, c.normal_index},
                                             uint32_t(mesh.positions.size()));
    if (fresh) {
      const int v = c.vertex_index;
      mesh.positions.push_back({vertices[3 * v], vertices[3 * v + 1], vertices[3 * v + 2]});
      if (!attrib.normals.empty()) {
        const int n = c.normal_index;
        mesh.normals.push_back(n >= 0 && size_t(3 * n + 2) < attrib.normals.size()
                                   ? Vec3{attrib.normals[3 * n], attrib.normals[3 * n + 1], attrib.normals[3 * n + 2]}
                                   : Vec3{0, 0, 0});
      }
      if (!attrib.texcoords.empty()) {
        const int t = c.texcoord_index;
        mesh.uvs.push_back(t >= 0 && size_t(2 * t + 1) < attrib.texcoords.size()
                               ? Vec2{attrib.texcoords[2 * t], 1.0f - attrib.texcoords[2 * t + 1]}
                               : Vec2{0, 0});
      }
    }
    return it->second;
  };
  for (const tinyobj::shape_t& shape : reader.GetShapes()) {
    size_t offset = 0;
    for (size_t f = 0; f < shape.mesh.num_face_vertices.size(); ++f) {
      const size_t k = shape.mesh.num_face_vertices[f];
      const int mat = f < shape.mesh.material_ids.size() ? shape.mesh.material_ids[f] : -1;
      const uint32_t material = mat >= 0 && size_t(mat) < materials.size() ? uint32_t(mat) : default_material;
      const uint32_t first = corner_index(shape.mesh.indices[offset]);
      for (size_t j = 1; j + 1 < k; ++j) {
        mesh.indices.push_back(first);
        mesh.indices.push_back(corner_index(shape.mesh.indices[offset + j]));
        mesh.indices.push_back(corner_index(shape.mesh.indices[offset + j + 1]));
        mesh.material_ids.push_back(material);
      }
      offset += k;
    }
  }
  if (!mesh.normals.empty() && mesh.normals.size() != mesh.positions.size()) mesh.normals.clear();
  if (!mesh.uvs.empty() && mesh.uvs.size() != mesh.positions.size()) mesh.uvs.clear();
  scene.meshes.push_back(std::move(mesh));
  return scene;
}

}  // namespace kestrel
