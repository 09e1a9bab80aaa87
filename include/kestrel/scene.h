// kestrel public API: triangle meshes, materials, textures and scenes; loading and validation.
#pragma once
#include <cstdint>
#include <string>
#include <vector>

#include "kestrel/types.h"

namespace kestrel {

/// An 8-bit RGBA texture, rows top to bottom (as decoded from PNG/JPEG).
struct Texture {
  std::string name;
  int width = 0, height = 0;
  std::vector<uint8_t> rgba;  ///< width * height * 4 bytes
};

/// A metallic-roughness material (glTF 2.0 model; OBJ/MTL mapped onto it).
struct Material {
  std::string name;
  Vec3 base_color{0.8f, 0.8f, 0.8f};  ///< linear RGB
  float metallic = 0.0f;              ///< [0, 1]
  float roughness = 1.0f;             ///< perceptual roughness, [0, 1] (GGX alpha = roughness^2)
  /// Weight of the dielectric (IOR 1.5) GGX coat over the diffuse base, [0, 1]: 0 = pure
  /// Lambertian, 1 = glTF's dielectric. MTL: max(Ks); glTF: 1. Unused where metallic = 1.
  float specular = 0.0f;
  Vec3 emission{0, 0, 0};               ///< linear RGB radiance scale (W/sr/m^2 units of the scene)
  int base_color_texture = -1;          ///< index into Scene::textures, or -1
  int metallic_roughness_texture = -1;  ///< glTF: G = roughness, B = metallic
  int emission_texture = -1;
  int normal_texture = -1;    ///< tangent space (glTF: +X along u, +Y against v), linear
  float normal_scale = 1.0f;  ///< glTF normalTexture.scale: multiplies the map's X and Y
  /// Cut-out opacity (glTF alphaMode, MTL d and map_d): `opaque` ignores alpha; where a
  /// `mask` material's alpha is below alpha_cutoff, its surface is not there (rays pass
  /// through: foliage cards, fences); a `blend` material's surface is there for a fraction
  /// alpha of the rays that meet it (stochastic transparency: thin glass, decals).
  enum class AlphaMode : uint8_t { opaque, mask, blend };
  AlphaMode alpha_mode = AlphaMode::opaque;
  float alpha = 1.0f;           ///< [0, 1]; glTF baseColorFactor's fourth value, MTL d
  float alpha_cutoff = 0.5f;    ///< mask: glTF alphaCutoff
  int alpha_texture = -1;       ///< multiplies alpha: its A channel (R with alpha_from_red)
  bool alpha_from_red = false;  ///< an MTL map_d without an alpha channel: a grey mask
  /// Glass (glTF KHR_materials_transmission, MTL illum 4, 6, 7, 9): the share of the
  /// non-metallic part that is a smooth or rough (roughness) dielectric interface letting light
  /// through, tinted by the base colour, instead of the diffuse base. [0, 1]
  float transmission = 0;
  float ior = 1.5f;  ///< index of refraction (glTF KHR_materials_ior, MTL Ni), >= 1
  /// Glass: a sheet (light goes straight through: a window pane; glTF's default without
  /// KHR_materials_volume) rather than the surface of a solid that refracts (the front face,
  /// counter-clockwise, outside).
  bool thin_walled = false;
  /// Glass that absorbs (glTF KHR_materials_volume): light crossing the solid keeps
  /// attenuation_color after attenuation_distance (Beer-Lambert); infinite = clear.
  Vec3 attenuation_color{1, 1, 1};
  float attenuation_distance = INFINITY;
};

/// A punctual light (glTF KHR_lights_punctual): a point, a spot or a directional light, in
/// world space. glTF's photometric units are taken 1:1 as kestrel's radiometric ones: a
/// point or spot light's `intensity` (candela) is its radiant intensity (radiance units x
/// m^2 per steradian), a directional light's (lux) the irradiance it gives a surface facing it.
struct Light {
  enum class Type { point, spot, directional };
  std::string name;
  Type type = Type::point;
  Vec3 position{0, 0, 0};    ///< point and spot
  Vec3 direction{0, 0, -1};  ///< spot and directional: the way the light travels (unit)
  Vec3 color{1, 1, 1};       ///< linear RGB, multiplies intensity
  float intensity = 1;
  float range = 0;  ///< > 0: glTF's smooth cut-off at this distance; 0 = none
  float inner_cone = 0, outer_cone = 0.7853982f;  ///< spot: radians, 0 <= inner < outer <= pi/2
};
/// "point", "spot", "directional".
const char* light_type_name(Light::Type type);
/// Why a light cannot be rendered ("" when it can): a NaN/Inf value, a negative colour,
/// intensity or range, a zero direction, or cone angles outside 0 <= inner < outer <= pi/2.
std::string light_problem(const Light& light);

/// A triangle mesh in world space. Triangle i is (indices[3i], indices[3i+1], indices[3i+2]);
/// normals and uvs are per vertex when present (same count as positions) or empty.
struct TriangleMesh {
  std::string name;
  std::vector<Vec3> positions;
  std::vector<Vec3> normals;
  std::vector<Vec2>
      uvs;  ///< glTF convention: (0, 0) is the top-left of a texture (OBJ v is flipped on load)
  std::vector<uint32_t> indices;
  std::vector<uint32_t> material_ids;  ///< one per triangle (index into Scene::materials)
  /// Per vertex (same count as positions) or empty: linear RGB in [0, 1] multiplying the
  /// material's base colour (glTF COLOR_0, OBJ "v x y z r g b").
  std::vector<Vec3> colors;
  size_t triangle_count() const { return indices.size() / 3; }
};

/// What validation found. Invalid triangles keep their ids (so OBJ numbering is preserved)
/// but never reach a builder.
struct ValidationReport {
  size_t triangle_count = 0;  ///< all triangles, valid or not
  size_t valid_triangle_count = 0;
  size_t nonfinite_triangle_count = 0;   ///< a vertex with a NaN or Inf coordinate
  size_t bad_index_triangle_count = 0;   ///< an index past the vertex array
  size_t degenerate_triangle_count = 0;  ///< zero area (collinear or repeated vertices)
  size_t empty_mesh_count = 0;           ///< meshes with no triangle
  /// One line, e.g. "66445 triangles: 66445 valid, 0 non-finite, 0 bad index, 0 degenerate".
  std::string summary() const;
};

/// A scene: meshes (prim ids run over meshes in order), materials and textures.
struct Scene {
  std::string source;  ///< file it was loaded from, or "builtin:NAME"
  std::vector<TriangleMesh> meshes;
  std::vector<Material> materials;
  std::vector<Texture> textures;
  std::vector<Light> lights;  ///< punctual lights (glTF KHR_lights_punctual)
  /// Problems that did not stop the load (e.g. a texture that could not be decoded).
  std::vector<std::string> warnings;
  size_t triangle_count() const;
};

/// Per-triangle validity over the whole scene (global prim ids) plus the counts.
struct SceneValidation {
  ValidationReport report;
  std::vector<uint8_t> valid;  ///< one per global prim id: 1 if the triangle may be built
};

/// Checks every triangle: finite vertices, indices in range, non-zero area.
SceneValidation validate_scene(const Scene& scene);

/// Bounds of every finite vertex used by a triangle (empty for an empty scene).
Bounds3 scene_bounds(const Scene& scene);

/// Loads an OBJ (+MTL), glTF or GLB file, or a built-in scene "builtin:NAME" (cornell_box,
/// lamp_hall, and the procedural soup, hairball, terrain and sphere_field: builtin_scene_names).
/// Throws Error naming the file (and line, where the format has lines) on failure.
Scene load_scene(const std::string& path);

/// Whether a path names a glTF file (.gltf or .glb, any case): load_scene reads it flattened,
/// GltfInstances as a two-level scene with its animation.
bool is_gltf_path(const std::string& path);

/// Names accepted by load_scene after "builtin:".
std::vector<std::string> builtin_scene_names();

}  // namespace kestrel
