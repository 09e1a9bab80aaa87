// glTF 2.0 (.gltf / .glb) through tinygltf: the default scene's node hierarchy is flattened
// to world space (one TriangleMesh per node that has a mesh, primitives in order), with
// metallic-roughness materials and decoded textures. Accessors are bounds-checked against
// their buffers before use, so a truncated or inconsistent file is an Error, never a read
// past the end.
#include <fmt/format.h>
#include <fmt/ranges.h>
#include <tiny_gltf.h>

#include "io/gltf_reader.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <filesystem>

#include <sys/stat.h>

#include "core/file_io.h"
#include "io/loaders.h"
#include "kestrel/error.h"

namespace kestrel {

namespace {

using namespace gltf;

}  // namespace

Scene load_gltf(const std::string& path) {
  const tinygltf::Model model = load_model(path);
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
    for (size_t i = 0; i < model.nodes.size(); ++i)
      roots.push_back(int(i));  // no scene: every node
  }
  // Depth-first over the hierarchy; the depth cap rejects cycles in malformed files.
  auto visit = [&](auto&& self, int node_index, const Mat4& parent, int depth) -> void {
    if (node_index < 0 || size_t(node_index) >= model.nodes.size())
      reader.fail(fmt::format("node {} does not exist", node_index));
    if (depth > 256)
      reader.fail(fmt::format("node {}: hierarchy deeper than 256 (cycle?)", node_index));
    const tinygltf::Node& node = model.nodes[node_index];
    const Mat4 world = mul(parent, node_matrix(node));
    if (node.mesh >= 0) {
      if (size_t(node.mesh) >= model.meshes.size())
        reader.fail(fmt::format("node {} names missing mesh {}", node_index, node.mesh));
      const tinygltf::Mesh& gm = model.meshes[node.mesh];
      TriangleMesh mesh;
      mesh.name = gm.name.empty() ? fmt::format("mesh{}", node.mesh) : gm.name;
      bool all_normals = true;
      for (const tinygltf::Primitive& prim : gm.primitives) {
        std::vector<Vec3> positions;
        std::vector<uint32_t> indices;
        if (!reader.read_triangles(prim, positions, indices))
          continue;  // points/lines/strips skipped
        std::vector<Vec3> normals;
        std::vector<Vec2> uvs;
        reader.read_normals_uvs(prim, positions.size(), normals, uvs);
        all_normals &= normals.size() == positions.size();
        const uint32_t base = uint32_t(mesh.positions.size());
        add_per_vertex(mesh.uvs, base, uvs, positions.size(), Vec2{0, 0});
        add_per_vertex(mesh.colors, base, reader.read_colors(prim, positions.size()),
                       positions.size(), Vec3{1, 1, 1});
        for (Vec3 p : positions) mesh.positions.push_back(transform_point(world, p));
        if (all_normals)
          for (Vec3 n : normals) mesh.normals.push_back(transform_normal(world, n));
        const uint32_t material =
            prim.material >= 0 && size_t(prim.material) < model.materials.size()
                ? uint32_t(prim.material)
                : default_material;
        // Out-of-range indices stay out of range after the offset (validation counts them).
        for (size_t i = 0; i + 2 < indices.size(); i += 3) {
          for (int k = 0; k < 3; ++k)
            mesh.indices.push_back(indices[i + k] < positions.size() ? base + indices[i + k]
                                                                     : 0xFFFFFFFFu);
          mesh.material_ids.push_back(material);
        }
      }
      if (!all_normals) mesh.normals.clear();
      scene.meshes.push_back(std::move(mesh));
    }
    if (auto light = node_light(path, model, node_index, world)) scene.lights.push_back(*light);
    for (int child : node.children) self(self, child, world, depth + 1);
  };
  for (int root : roots) visit(visit, root, identity(), 0);
  return scene;
}

namespace gltf {

std::optional<Light> node_light(const std::string& path, const tinygltf::Model& model,
                                int node_index, const Mat4& world) {
  const tinygltf::Node& node = model.nodes[size_t(node_index)];
  const auto ext = node.extensions.find("KHR_lights_punctual");
  if (ext == node.extensions.end() || !ext->second.IsObject() || !ext->second.Has("light"))
    return std::nullopt;
  const tinygltf::Value& v = ext->second.Get("light");
  const int index = v.IsNumber() || v.IsInt() ? v.GetNumberAsInt() : -1;
  if (index < 0 || size_t(index) >= model.lights.size())
    throw Error(ErrorCode::parse_error,
                fmt::format("{}: node {} names missing light {}", path, node_index, index));
  const tinygltf::Light& gl = model.lights[size_t(index)];
  const std::string what =
      fmt::format("{}: light {} '{}' (node {})", path, index, gl.name, node_index);
  Light l;
  l.name = gl.name.empty() ? fmt::format("light{}", index) : gl.name;
  if (gl.type == "point")
    l.type = Light::Type::point;
  else if (gl.type == "spot")
    l.type = Light::Type::spot;
  else if (gl.type == "directional")
    l.type = Light::Type::directional;
  else
    throw Error(
        ErrorCode::parse_error,
        fmt::format("{}: unknown type '{}' (expected point, spot or directional)", what, gl.type));
  if (!gl.color.empty()) {
    if (gl.color.size() != 3)
      throw Error(ErrorCode::parse_error, fmt::format("{}: color must have 3 components", what));
    l.color = {float(gl.color[0]), float(gl.color[1]), float(gl.color[2])};
  }
  l.intensity = float(gl.intensity);
  l.range = float(gl.range);
  l.inner_cone = float(gl.spot.innerConeAngle);
  l.outer_cone = float(gl.spot.outerConeAngle);
  if (!place_light(l, world)) l.direction = {0, 0, 0};  // light_problem reports it
  if (const std::string p = light_problem(l); !p.empty())
    throw Error(ErrorCode::parse_error, fmt::format("{}: {}", what, p));
  return l;
}

void check_node_tree(const std::string& path, const tinygltf::Model& model) {
  // Every child exists, no node has two parents (shared children would make a DAG whose
  // flattening grows exponentially), no node is its own ancestor, scene roots have no parent.
  const size_t n = model.nodes.size();
  std::vector<int> parent(n, -1);
  for (size_t i = 0; i < n; ++i)
    for (int c : model.nodes[i].children) {
      if (c < 0 || size_t(c) >= n)
        throw Error(ErrorCode::parse_error,
                    fmt::format("{}: node {}: child {} does not exist", path, i, c));
      if (parent[size_t(c)] >= 0)
        throw Error(
            ErrorCode::parse_error,
            fmt::format("{}: node {} is a child of both node {} and node {} (the node graph "
                        "must be a tree)",
                        path, c, parent[size_t(c)], i));
      parent[size_t(c)] = int(i);
    }
  for (size_t i = 0; i < n; ++i) {  // walk up: a chain longer than n is a cycle
    size_t steps = 0;
    for (int p = parent[i]; p >= 0; p = parent[size_t(p)])
      if (++steps > n || size_t(p) == i)
        throw Error(ErrorCode::parse_error,
                    fmt::format("{}: node {} is its own ancestor (a cycle)", path, i));
  }
  for (size_t s = 0; s < model.scenes.size(); ++s) {
    std::vector<char> listed(n, 0);
    for (int r : model.scenes[s].nodes) {
      if (r < 0 || size_t(r) >= n)
        throw Error(ErrorCode::parse_error,
                    fmt::format("{}: scene {}: node {} does not exist", path, s, r));
      if (parent[size_t(r)] >= 0 || listed[size_t(r)]++)
        throw Error(
            ErrorCode::parse_error,
            fmt::format("{}: scene {}: node {} is listed as a root twice or also has a parent",
                        path, s, r));
    }
  }
}

Material convert_material(const tinygltf::Material& m, const tinygltf::Model& model) {
  Material out;
  out.name = m.name;
  const auto& pbr = m.pbrMetallicRoughness;
  if (pbr.baseColorFactor.size() >= 3)
    out.base_color = {float(pbr.baseColorFactor[0]), float(pbr.baseColorFactor[1]),
                      float(pbr.baseColorFactor[2])};
  out.metallic = float(pbr.metallicFactor);
  out.roughness = float(pbr.roughnessFactor);
  out.specular = 1.0f;  // glTF dielectrics: Fresnel with F0 = 0.04 (IOR 1.5)
  // KHR_materials_specular: the coat's weight is specularFactor times the brightest channel of
  // specularColorFactor (kestrel's coat is uncoloured), clamped to [0, 1]; 0 leaves the
  // Lambertian base alone, as an MTL material without Ks. A non-finite factor stays non-finite
  // and is refused with the material's name when the scene is rendered.
  if (auto spec = m.extensions.find("KHR_materials_specular"); spec != m.extensions.end()) {
    const tinygltf::Value& v = spec->second;
    double weight = v.Has("specularFactor") ? v.Get("specularFactor").GetNumberAsDouble() : 1.0;
    if (v.Has("specularColorFactor") && v.Get("specularColorFactor").IsArray()) {
      const tinygltf::Value& c = v.Get("specularColorFactor");
      double brightest = 0;
      for (int i = 0; i < int(std::min<size_t>(c.ArrayLen(), 3)); ++i) {
        const double x = c.Get(i).GetNumberAsDouble();
        if (!std::isfinite(x)) {  // kept, so that the material is refused
          brightest = x;
          break;
        }
        brightest = std::max(brightest, x);
      }
      weight *= brightest;
    }
    out.specular = std::isfinite(weight) ? std::clamp(float(weight), 0.0f, 1.0f) : float(weight);
  }
  // Glass: KHR_materials_transmission's factor (a transmissionTexture is not read: the factor
  // holds everywhere), KHR_materials_ior (0, the extension's "F0 = 1", as a very large IOR),
  // KHR_materials_volume: a thickness > 0 makes the mesh a solid that refracts, with its
  // attenuation; otherwise a thin sheet (glTF's rule). Non-finite values are kept, so that
  // the material is refused by name when the scene is rendered.
  auto number = [&](const char* extension, const char* key, double fallback) {
    const auto it = m.extensions.find(extension);
    if (it == m.extensions.end() || !it->second.Has(key)) return fallback;
    const tinygltf::Value& v = it->second.Get(key);
    return v.IsNumber() ? v.GetNumberAsDouble() : fallback;
  };
  const double transmission = number("KHR_materials_transmission", "transmissionFactor", 0);
  out.transmission = std::isfinite(transmission) ? std::clamp(float(transmission), 0.0f, 1.0f)
                                                 : float(transmission);
  const double ior = number("KHR_materials_ior", "ior", 1.5);
  out.ior = ior == 0 ? 1e4f : float(ior);
  out.thin_walled = !(number("KHR_materials_volume", "thicknessFactor", 0) > 0);
  if (!out.thin_walled) {
    out.attenuation_distance =
        float(number("KHR_materials_volume", "attenuationDistance", double(INFINITY)));
    if (const auto it = m.extensions.find("KHR_materials_volume");
        it->second.Has("attenuationColor") && it->second.Get("attenuationColor").IsArray()) {
      const tinygltf::Value& c = it->second.Get("attenuationColor");
      for (int i = 0; i < int(std::min<size_t>(c.ArrayLen(), 3)); ++i)
        out.attenuation_color[i] = float(c.Get(i).GetNumberAsDouble());
    }
  }
  float strength = 1.0f;
  auto ext = m.extensions.find("KHR_materials_emissive_strength");
  if (ext != m.extensions.end() && ext->second.Has("emissiveStrength"))
    strength = float(ext->second.Get("emissiveStrength").GetNumberAsDouble());
  if (m.emissiveFactor.size() == 3)
    out.emission = {float(m.emissiveFactor[0]) * strength, float(m.emissiveFactor[1]) * strength,
                    float(m.emissiveFactor[2]) * strength};
  auto texture = [&](int index) {
    return index >= 0 && size_t(index) < model.textures.size() ? index : -1;
  };
  out.base_color_texture = texture(pbr.baseColorTexture.index);
  out.metallic_roughness_texture = texture(pbr.metallicRoughnessTexture.index);
  out.emission_texture = texture(m.emissiveTexture.index);
  out.normal_texture = texture(m.normalTexture.index);
  out.normal_scale = float(m.normalTexture.scale);
  // Alpha: baseColorFactor's fourth value times the base colour texture's A channel.
  if (m.alphaMode == "MASK" || m.alphaMode == "BLEND") {
    out.alpha_mode = m.alphaMode == "MASK" ? Material::AlphaMode::mask : Material::AlphaMode::blend;
    out.alpha = pbr.baseColorFactor.size() == 4 ? float(pbr.baseColorFactor[3]) : 1.0f;
    out.alpha_cutoff = float(m.alphaCutoff);
    out.alpha_texture = out.base_color_texture;
  }
  return out;
}

Texture convert_texture(const tinygltf::Texture& t, const tinygltf::Model& model) {
  Texture out;
  out.name = t.name;
  if (t.source < 0 || size_t(t.source) >= model.images.size()) return out;
  const tinygltf::Image& img = model.images[t.source];
  if (out.name.empty()) out.name = img.name.empty() ? img.uri : img.name;
  if (img.bits != 8 || img.component < 1 || img.component > 4 || img.width <= 0 ||
      img.height <= 0 || img.image.size() < size_t(img.width) * img.height * img.component)
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

namespace {

constexpr uint64_t max_gltf_file_bytes = uint64_t(4) << 30;

// tinygltf's file access, replaced: only regular files, bounded, and paths taken literally
// (its default expands them like a shell would).
bool file_exists(const std::string& path, void*) {
  struct stat st {};
  return ::stat(path.c_str(), &st) == 0;
}
std::string expand_path(const std::string& path, void*) {
  return path;
}
bool read_whole_file(std::vector<unsigned char>* out, std::string* err, const std::string& path,
                     void*) {
  try {
    const std::string data =
        read_bounded_file(path, max_gltf_file_bytes, "glTF file, buffer or image");
    out->assign(data.begin(), data.end());
    return true;
  } catch (const Error& e) {
    if (err) *err += std::string(e.what()) + "\n";
    return false;
  }
}

// Embedded and external images, decoded by kestrel's checked decoder (dimensions and the
// decoded size bounded before anything is allocated).
bool load_image(tinygltf::Image* image, const int index, std::string* err, std::string*, int, int,
                const unsigned char* bytes, int size, void*) {
  std::string problem;
  int w = 0, h = 0;
  std::vector<unsigned char> rgba;
  if (size <= 0 || !decode_rgba8(bytes, size_t(size), w, h, rgba, problem)) {
    if (err) *err += fmt::format("image {}: {}\n", index, problem.empty() ? "empty" : problem);
    return false;
  }
  image->width = w, image->height = h, image->component = 4, image->bits = 8;
  image->pixel_type = TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE;
  image->image = std::move(rgba);
  return true;
}

}  // namespace

tinygltf::Model load_model(const std::string& path) {
  require_readable_file(path);
  tinygltf::TinyGLTF loader;
  loader.SetFsCallbacks(tinygltf::FsCallbacks{&file_exists, &expand_path, &read_whole_file,
                                              &tinygltf::WriteWholeFile, nullptr});
  loader.SetImageLoader(&load_image, nullptr);
  tinygltf::Model model;
  std::string err, warn;
  const bool binary = lower_extension(path) == ".glb";
  if (binary && regular_file_size(path, "glTF file") < 20)
    throw Error(
        ErrorCode::parse_error,
        fmt::format("{}: too short for a GLB file (header and one chunk take 20 bytes)", path));
  bool ok = false;
  try {  // tinygltf throws (e.g. std::out_of_range) on some malformed files
    ok = binary ? loader.LoadBinaryFromFile(&model, &err, &warn, path)
                : loader.LoadASCIIFromFile(&model, &err, &warn, path);
  } catch (const Error&) {
    throw;
  } catch (const std::exception&) {
    throw Error(ErrorCode::parse_error,
                fmt::format("{}: not a valid {} file (its reader stopped on malformed data)", path,
                            binary ? "GLB" : "glTF"));
  }
  if (!ok) {
    while (!err.empty() && (err.back() == '\n' || err.back() == '\r')) err.pop_back();
    throw Error(ErrorCode::parse_error,
                fmt::format("{}: {}", path, err.empty() ? "not a valid glTF file" : err));
  }
  // A required extension changes what the file's data mean (compressed meshes, transformed
  // texture coordinates...): glTF asks a loader that does not read it to refuse the file.
  static const char* const readable[] = {
      "KHR_lights_punctual",        "KHR_materials_emissive_strength",
      "KHR_materials_ior",          "KHR_materials_specular",
      "KHR_materials_transmission", "KHR_materials_volume",
      "KHR_mesh_quantization",      "KHR_texture_transform"};
  for (const std::string& ext : model.extensionsRequired)
    if (std::find(std::begin(readable), std::end(readable), ext) == std::end(readable))
      throw Error(ErrorCode::unsupported,
                  fmt::format("{}: requires the glTF extension {}, which kestrel does not read "
                              "(it reads {})",
                              path, ext, fmt::join(readable, ", ")));
  check_node_tree(path, model);
  return model;
}
}  // namespace gltf

}  // namespace kestrel
