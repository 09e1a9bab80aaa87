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
#include <cctype>
#include <charconv>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <map>
#include <sstream>
#include <unordered_map>

#include <sys/stat.h>

#include "core/color.h"
#include "core/file_io.h"
#include "io/loaders.h"
#include "kestrel/error.h"

namespace kestrel {

namespace {

constexpr uint64_t max_obj_bytes = uint64_t(8) << 30;

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

// tinyobjloader keeps a face's corner count in a byte: longer faces are split here (below).
constexpr int max_face_corners = 255;

struct ObjCheck {
  std::vector<size_t> nonfinite;  // vertex ids with a NaN or Inf coordinate
  std::vector<std::pair<size_t, size_t>>
      long_faces;  // [begin, end) byte ranges of faces over max_face_corners
};

// Checks `v x y z [w]` and `f a b c ...` (each a, a/b, a//c or a/b/c, non-zero integers that
// fit tinyobjloader's int: a larger one would wrap to a plausible small index). Finds the
// (0-based) ids of vertices with a NaN or Inf coordinate (tinyobjloader reads those as 0,
// which would turn a corrupt vertex into a plausible one) and faces too long for it.
ObjCheck check_obj_lines(const std::string& path, const std::string& text) {
  ObjCheck result;
  std::vector<size_t>& nonfinite = result.nonfinite;
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
          if (ec == std::errc::result_out_of_range ||
              (ec == std::errc() && (v > INT32_MAX || v < -INT32_MAX)))
            malformed(path, line,
                      fmt::format("face index '{}' is out of range (at most {})",
                                  std::string(q, size_t(std::find_if(q, eol,
                                                                     [](char c) {
                                                                       return c == ' ' ||
                                                                              c == '/' ||
                                                                              c == '\t' ||
                                                                              c == '\r';
                                                                     }) -
                                                        q)),
                                  INT32_MAX));
          if (ec != std::errc() || v == 0)
            malformed(path, line, "face index must be a non-zero integer");
          q = next;
          if (q < eol && *q == '/')
            ++q;
          else
            break;
        }
        if (q < eol && *q != ' ' && *q != '\t' && *q != '\r')
          malformed(path, line, "malformed face corner");
        ++corners;
      }
      if (corners < 3)
        malformed(path, line, fmt::format("face has {} corners, needs at least 3", corners));
      if (corners > max_face_corners)
        result.long_faces.emplace_back(size_t(p - text.data()), size_t(eol - text.data()));
    }
    p = eol + 1;
  }
  return result;
}

// The OBJ with every face of more than 255 corners written as several faces that continue
// its fan: (v0, v1 .. v254), (v0, v254 .. v508), ... give the triangles (v0, vi, vi+1) in the
// same order, so prim ids are those of the one long face.
std::string split_long_faces(const std::string& text,
                             const std::vector<std::pair<size_t, size_t>>& faces) {
  std::string out;
  out.reserve(text.size() + faces.size() * 64);
  size_t at = 0;
  for (const auto& [begin, end] : faces) {
    out.append(text, at, begin - at);
    std::vector<std::string> corners;
    std::istringstream line(text.substr(begin, end - begin));
    std::string token;
    line >> token;  // "f"
    while (line >> token) corners.push_back(token);
    for (size_t first = 1; first + 1 < corners.size(); first += max_face_corners - 2) {
      out += "f " + corners[0];
      for (size_t k = first; k < std::min(corners.size(), first + max_face_corners - 1); ++k)
        out += " " + corners[k];
      out += "\n";
    }
    at = end;
    if (at < text.size() && text[at] == '\n') ++at;
  }
  out.append(text, at, std::string::npos);
  return out;
}

// tinyobjloader reads a bad number in a material as 0: the numeric statements of each MTL are
// checked first, so `Kd abc` is an error naming the file and line.
void check_mtl_lines(const std::string& path, const std::string& text) {
  static const std::map<std::string, int> numbers = {
      {"Ka", 3}, {"Kd", 3}, {"Ks", 3}, {"Ke", 3},  {"Kt", 3},    {"Tf", 3},
      {"Ns", 1}, {"Ni", 1}, {"d", 1},  {"Tr", 1},  {"illum", 1}, {"Pr", 1},
      {"Pm", 1}, {"Ps", 1}, {"Pc", 1}, {"Pcr", 1}, {"aniso", 1}, {"anisor", 1}};
  std::istringstream in(text);
  std::string line_text;
  size_t line = 0;
  while (std::getline(in, line_text)) {
    ++line;
    std::istringstream words(line_text);
    std::string key;
    if (!(words >> key)) continue;
    auto it = numbers.find(key);
    if (it == numbers.end()) continue;
    int given = 0;
    std::string word;
    while (words >> word) {
      float v;
      const char* b = word.data();
      if (given == 0 && (word == "spectral" || word == "xyz"))
        break;  // other forms of colours: left to the library
      if (!parse_float(b, word.data() + word.size(), v))
        malformed(path, line, fmt::format("'{}' needs numbers, got '{}'", key, word));
      ++given;
    }
    if (given != 0 && given != 1 && given != it->second)
      malformed(path, line, fmt::format("'{}' takes {} numbers, got {}", key, it->second, given));
    if (given == 0 && word != "spectral" && word != "xyz")
      malformed(path, line, fmt::format("'{}' needs a value", key));
  }
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

bool is_glass(const tinyobj::material_t& m) {
  return m.illum == 4 || m.illum == 6 || m.illum == 7 || m.illum == 9;
}

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
  // Glass (illum 4, 6, 7, 9: the MTL models with refraction or glass): a solid refracting
  // at Ni (1.5 where not above 1: tinyobj reads a missing Ni as 1), tinted by Tf (white
  // where Tf is black or missing), smooth unless Ns or Pr say otherwise; its transparency
  // is the glass's (load_obj reads no cut-out for it).
  if (is_glass(m)) {
    out.transmission = 1;
    out.ior = m.ior > 1.0f ? m.ior : 1.5f;
    if (!(m.roughness > 0) && !(m.shininess > 1)) out.roughness = 0;  // (tinyobj: Ns 1)
    const Vec3 tf{m.transmittance[0], m.transmittance[1], m.transmittance[2]};
    out.base_color = tf.x > 0 || tf.y > 0 || tf.z > 0 ? tf : Vec3{1, 1, 1};
  }
  return out;
}

// A file an OBJ or MTL names (material library, texture), as written, or else as Windows
// tools write names: with backslashes, or in another letter case than the file on disk
// (resolved one folder at a time, case-insensitively). The name as written when nothing
// matches (the error or warning then names it).
std::string resolve_file_name(const std::filesystem::path& dir, const std::string& name) {
  namespace fs = std::filesystem;
  std::error_code ec;
  const fs::path as_written = dir / name;
  if (fs::exists(as_written, ec)) return as_written.string();
  std::string slashed = name;
  std::replace(slashed.begin(), slashed.end(), '\\', '/');
  if (fs::exists(dir / slashed, ec)) return (dir / slashed).string();
  auto lower = [](std::string x) {
    for (char& c : x) c = char(std::tolower(static_cast<unsigned char>(c)));
    return x;
  };
  fs::path at = dir.empty() ? fs::path(".") : dir;
  for (const fs::path& part : fs::path(slashed)) {
    if (part.empty() || part == ".") continue;
    if (fs::exists(at / part, ec)) {
      at /= part;
      continue;
    }
    const std::string want = lower(part.string());
    bool found = false;
    for (fs::directory_iterator e(at, ec), end; !ec && e != end; e.increment(ec))
      if (lower(e->path().filename().string()) == want) {
        at = e->path(), found = true;
        break;
      }
    if (!found) return as_written.string();
  }
  return at.string();
}

}  // namespace

Scene load_obj(const std::string& path) {
  std::string text = read_bounded_file(path, max_obj_bytes, "OBJ scene");
  const ObjCheck check = check_obj_lines(path, text);
  const std::vector<size_t>& nonfinite_vertices = check.nonfinite;
  if (!check.long_faces.empty()) text = split_long_faces(text, check.long_faces);

  // The MTL files named by `mtllib` are read here and handed over as text, so a missing
  // .mtl is not fatal (its materials fall back to the default).
  const std::filesystem::path dir = std::filesystem::path(path).parent_path();
  // A missing .mtl is a warning; one that names a folder, a FIFO or a device, or is too large
  // or malformed, is an error naming it.
  std::string mtl_text;
  std::vector<std::string> warnings;
  {
    std::istringstream obj_stream(text);
    std::string line_text;
    while (std::getline(obj_stream, line_text)) {
      if (line_text.rfind("mtllib", 0) != 0) continue;
      std::string name = line_text.substr(6);
      name.erase(0, name.find_first_not_of(" \t"));
      while (!name.empty() && (name.back() == '\r' || name.back() == ' ')) name.pop_back();
      const std::string mtl_path = name.empty() ? dir.string() : resolve_file_name(dir, name);
      struct stat st {};
      if (name.empty() || ::stat(mtl_path.c_str(), &st) != 0) {
        warnings.push_back(fmt::format(
            "{}: material library '{}' not found; its materials use the default", path, name));
        continue;
      }
      const std::string mtl =
          read_bounded_file(mtl_path, max_obj_bytes, "material library (mtllib)");
      check_mtl_lines(mtl_path, mtl);
      mtl_text.append(mtl).append("\n");
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
  scene.warnings = std::move(warnings);
  if (!check.long_faces.empty())
    scene.warnings.push_back(fmt::format(
        "{}: {} faces of more than {} corners fan-triangulated in pieces (same triangles)", path,
        check.long_faces.size(), max_face_corners));
  // Texture maps named by the MTL (map_Kd, map_Ke), each file decoded once. A missing or
  // undecodable image leaves the material untextured and a warning naming the file and the
  // problem in Scene::warnings; it does not fail the scene.
  std::map<std::string, int> texture_of;
  auto texture = [&](const std::string& name) -> int {
    if (name.empty()) return -1;
    auto [it, fresh] = texture_of.try_emplace(name, -1);
    if (fresh) {
      try {
        scene.textures.push_back(load_texture(resolve_file_name(dir, name)));
        it->second = int(scene.textures.size() - 1);
      } catch (const Error& e) {
        scene.warnings.push_back(
            fmt::format("{}: texture '{}' not used: {}", path, name, e.what()));
      }
    }
    return it->second;
  };
  for (const auto& m : materials) {
    Material material = convert_material(m);
    material.base_color_texture = texture(m.diffuse_texname);
    material.emission_texture = texture(m.emissive_texname);
    // map_d: a cut-out mask (its A channel, or its grey level when it has no alpha); d < 1
    // alone (or Tr > 0): a surface that lets the rest of the light through, stochastically.
    // Glass has neither: its d is the glass's transparency (convert_material).
    if (is_glass(m)) {
      scene.materials.push_back(material);
      continue;
    }
    material.alpha = m.dissolve;
    if (const int mask = texture(m.alpha_texname); mask >= 0) {
      const std::vector<uint8_t>& rgba = scene.textures[size_t(mask)].rgba;
      bool has_alpha = false;
      for (size_t i = 3; i < rgba.size() && !has_alpha; i += 4) has_alpha = rgba[i] != 255;
      material.alpha_mode = Material::AlphaMode::mask;
      material.alpha_texture = mask;
      material.alpha_from_red = !has_alpha;
    } else if (m.dissolve < 1.0f) {
      material.alpha_mode = Material::AlphaMode::blend;
    }
    scene.materials.push_back(material);
  }
  const uint32_t default_material = uint32_t(scene.materials.size());
  scene.materials.push_back(Material{.name = "default"});

  TriangleMesh mesh;
  mesh.name = std::filesystem::path(path).stem().string();
  const size_t vertex_count = vertices.size() / 3;
  const bool has_extra = !attrib.normals.empty() || !attrib.texcoords.empty();
  std::unordered_map<CornerKey, uint32_t, CornerHash> corner_of;
  // Vertex colours ("v x y z r g b" on every vertex: tinyobj keeps none otherwise) are display
  // colours, as MeshLab and Blender write them: sRGB-decoded, clamped to [0, 1] (NaN as 0).
  std::vector<Vec3> colors;
  if (attrib.colors.size() == 3 * vertex_count) {
    colors.resize(vertex_count);
    for (size_t i = 0; i < 3 * vertex_count; ++i) {
      const float c = attrib.colors[i] >= 0 ? std::min(attrib.colors[i], 1.0f) : 0.0f;
      colors[i / 3][int(i % 3)] = srgb_to_linear(c);
    }
  }
  if (!has_extra) {
    mesh.positions.resize(vertex_count);
    for (size_t i = 0; i < vertex_count; ++i)
      mesh.positions[i] = {vertices[3 * i], vertices[3 * i + 1], vertices[3 * i + 2]};
    mesh.colors = colors;
  }
  // Out-of-range corners map to an index past the vertex array: validation counts them.
  const uint32_t bad_index = 0xFFFFFFFFu;
  auto corner_index = [&](const tinyobj::index_t& c) -> uint32_t {
    if (c.vertex_index < 0 || size_t(c.vertex_index) >= vertex_count) return bad_index;
    if (!has_extra) return uint32_t(c.vertex_index);
    auto [it, fresh] =
        corner_of.try_emplace(CornerKey{c.vertex_index, c.texcoord_index, c.normal_index},
                              uint32_t(mesh.positions.size()));
    if (fresh) {
      const size_t v =
          size_t(c.vertex_index);  // in range (checked above); size_t: no int overflow in 3 v
      mesh.positions.push_back({vertices[3 * v], vertices[3 * v + 1], vertices[3 * v + 2]});
      if (!attrib.normals.empty()) {
        // Indices in size_t: 3 * n overflows an int for n near 2^31 (found by fuzz_obj).
        const size_t n = c.normal_index >= 0 ? size_t(c.normal_index) : SIZE_MAX / 4;
        mesh.normals.push_back(
            3 * n + 2 < attrib.normals.size()
                ? Vec3{attrib.normals[3 * n], attrib.normals[3 * n + 1], attrib.normals[3 * n + 2]}
                : Vec3{0, 0, 0});
      }
      if (!colors.empty()) mesh.colors.push_back(colors[v]);
      if (!attrib.texcoords.empty()) {
        const size_t t = c.texcoord_index >= 0 ? size_t(c.texcoord_index) : SIZE_MAX / 4;
        mesh.uvs.push_back(2 * t + 1 < attrib.texcoords.size()
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
      const uint32_t material =
          mat >= 0 && size_t(mat) < materials.size() ? uint32_t(mat) : default_material;
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
  if (!mesh.colors.empty() && mesh.colors.size() != mesh.positions.size()) mesh.colors.clear();
  scene.meshes.push_back(std::move(mesh));
  return scene;
}

}  // namespace kestrel
