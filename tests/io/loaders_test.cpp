// Scene loading: every shared scene loads with the triangle counts of its README; bad input
// gives an Error naming the file (and line); validation counts and skips bad triangles.
#include <gtest/gtest.h>

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>

#include "kestrel/kestrel.h"
#include "support/oracles.h"

namespace kestrel {
namespace {

// Runs f and returns the Error it throws (fails the test when it does not throw).
template <class F>
Error error_of(F&& f) {
  try {
    f();
  } catch (const Error& e) {
    return e;
  }
  ADD_FAILURE() << "expected a kestrel::Error";
  return Error(ErrorCode::invalid_argument, "");
}

void expect_mentions(const Error& e, const std::string& text) {
  EXPECT_NE(std::string(e.what()).find(text), std::string::npos)
      << "'" << e.what() << "' lacks '" << text << "'";
}

// A glTF file of one triangle whose primitive uses material 0 of `materials` (a JSON array);
// `extra`: more top-level members, each followed by a comma.
std::string one_triangle_gltf(const std::string& name, const std::string& materials,
                              const std::string& extra = "") {
  return test::write_temp_file(name, R"({
    "asset": {"version": "2.0"}, "scene": 0, "scenes": [{"nodes": [0]}], "nodes": [{"mesh": 0}],
    "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "material": 0}]}], )" +
                                         extra + R"("materials": )" + materials + R"(,
    "buffers": [{"byteLength": 36,
                 "uri": "data:application/octet-stream;base64,AAAAAAAAAAAAAAAAAACAPwAAAAAAAAAAAAAAAAAAgD8AAAAA"}],
    "bufferViews": [{"buffer": 0, "byteOffset": 0, "byteLength": 36}],
    "accessors": [{"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3",
                   "min": [0, 0, 0], "max": [1, 1, 0]}]})");
}

struct SceneCount {
  const char* rel;
  size_t triangles;
};

class SharedScenes : public ::testing::TestWithParam<SceneCount> {};

TEST_P(SharedScenes, LoadWithTheReadmeTriangleCount) {
  auto path = test::shared_scene(GetParam().rel);
  if (!path) GTEST_SKIP() << "shared scenes not found";
  const Scene scene = load_scene(*path);
  const SceneValidation v = validate_scene(scene);
  EXPECT_EQ(scene.triangle_count(), GetParam().triangles) << v.report.summary();
  EXPECT_GT(v.report.valid_triangle_count, 0u);
  EXPECT_FALSE(scene.materials.empty());
}

// Scene-level (flattened) counts from ../shared/scenes/README.md.
INSTANTIATE_TEST_SUITE_P(
    All, SharedScenes,
    ::testing::Values(SceneCount{"cornell_box/cornell_box.obj", 36},
                      SceneCount{"teapot/teapot.obj", 6320},
                      SceneCount{"dabrovic_sponza/sponza.obj", 66445},
                      SceneCount{"stanford_bunny/stanford_bunny.obj", 69451},
                      SceneCount{"lamborghini/lamborghini.obj", 145917},
                      SceneCount{"bunny_grid/bunny_grid.obj", 1111218},
                      SceneCount{"gltf_flight_helmet/FlightHelmet.gltf", 94722},
                      SceneCount{"gltf_water_bottle/WaterBottle.gltf", 4510},
                      SceneCount{"gltf_box_animated/BoxAnimated.gltf", 254},
                      SceneCount{"gltf_cesium_milk_truck/CesiumMilkTruck.gltf", 3624},
                      SceneCount{"gltf_truck_fleet/truck_fleet.gltf", 231936},
                      SceneCount{"gltf_animated_morph_cube/AnimatedMorphCube.gltf", 12},
                      SceneCount{"gltf_morph_stress_test/MorphStressTest.gltf", 2412},
                      SceneCount{"gltf_fox/Fox.glb", 576},
                      SceneCount{"gltf_cornell_box/cornell_box.gltf", 36}),
    [](const auto& info) {
      std::string s = std::filesystem::path(info.param.rel).parent_path().string();
      for (char& c : s)
        if (!std::isalnum(static_cast<unsigned char>(c))) c = '_';
      return s;
    });

TEST(Gltf, CornellBoxMatchesTheObjTriangleForTriangle) {
  auto obj = test::shared_scene("cornell_box/cornell_box.obj");
  auto gltf = test::shared_scene("gltf_cornell_box/cornell_box.gltf");
  if (!obj || !gltf) GTEST_SKIP();
  const test::Soup a = test::flatten(load_scene(*obj)), b = test::flatten(load_scene(*gltf));
  ASSERT_EQ(a.triangles.size(), b.triangles.size());
  for (size_t i = 0; i < a.triangles.size(); ++i)
    for (int k = 0; k < 3; ++k) {
      const Vec3 p = k == 0 ? a.triangles[i].v0 : k == 1 ? a.triangles[i].v1 : a.triangles[i].v2;
      const Vec3 q = k == 0 ? b.triangles[i].v0 : k == 1 ? b.triangles[i].v1 : b.triangles[i].v2;
      EXPECT_NEAR(p.x, q.x, 1e-5f);
      EXPECT_NEAR(p.y, q.y, 1e-5f);
      EXPECT_NEAR(p.z, q.z, 1e-5f);
    }
  // The light keeps its emission (KHR_materials_emissive_strength).
  const Scene s = load_scene(*gltf);
  bool emissive = false;
  for (const Material& m : s.materials) emissive |= m.emission.x > 1.0f;
  EXPECT_TRUE(emissive);
}

TEST(Gltf, TexturesAndMaterialsAreRead) {
  auto path = test::shared_scene("gltf_water_bottle/WaterBottle.gltf");
  if (!path) GTEST_SKIP();
  const Scene s = load_scene(*path);
  ASSERT_FALSE(s.textures.empty());
  EXPECT_GT(s.textures[0].width, 0);
  EXPECT_EQ(s.textures[0].rgba.size(), size_t(s.textures[0].width) * s.textures[0].height * 4);
  ASSERT_GE(s.materials.size(), 1u);
  EXPECT_GE(s.materials[0].base_color_texture, 0);
  EXPECT_GE(s.materials[0].metallic_roughness_texture, 0);
  EXPECT_FALSE(s.meshes[0].uvs.empty());
  EXPECT_FALSE(s.meshes[0].normals.empty());
}

TEST(Obj, MtlTexturesAreDecoded) {
  auto path = test::shared_scene("dabrovic_sponza/sponza.obj");
  if (!path) GTEST_SKIP();
  const Scene s = load_scene(*path);
  int textured = 0;
  for (const Material& m : s.materials)
    if (m.base_color_texture >= 0) {
      ++textured;
      const Texture& t = s.textures[m.base_color_texture];
      EXPECT_GT(t.width, 0);
      EXPECT_EQ(t.rgba.size(), size_t(t.width) * t.height * 4);
    }
  EXPECT_GT(textured, 0);
  EXPECT_FALSE(s.meshes[0].uvs.empty());
}

// Texture names as Windows tools write them: backslashes and another letter case than the
// files on disk (sub/tex.tga named as "SUB\\Tex.TGA") still find the file.
TEST(Obj, TextureNamesWithBackslashesAndOtherCaseFindTheirFiles) {
  const std::filesystem::path dir = test::test_temp_dir() / "winpaths";
  std::filesystem::create_directories(dir / "sub");
  std::string tga(18, '\0');
  tga[2] = 2, tga[12] = 1, tga[14] = 1, tga[16] = 24, tga[17] = 0x20;
  tga += std::string("\x10\x20\x30", 3);
  std::ofstream(dir / "sub" / "tex.tga", std::ios::binary) << tga;
  std::ofstream(dir / "w.mtl") << "newmtl m\nKd 1 1 1\nmap_Kd SUB\\Tex.TGA\n";
  std::ofstream(dir / "w.obj") << "mtllib w.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nusemtl m\nf 1 2 3\n";
  const Scene s = load_scene((dir / "w.obj").string());
  ASSERT_EQ(s.textures.size(), 1u) << (s.warnings.empty() ? "" : s.warnings[0]);
  EXPECT_EQ(s.textures[0].width, 1);
  EXPECT_EQ(s.textures[0].rgba[0], 0x30);  // TGA stores BGR
  EXPECT_TRUE(s.warnings.empty());
}

TEST(Obj, FanTriangulationFollowsFileOrder) {
  const std::string path = test::write_temp_file(
      "quad.obj", "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 0 0 1\nf 1 2 3 4\nf 1 2 5\n");
  const Scene s = load_scene(path);
  ASSERT_EQ(s.triangle_count(), 3u);
  const auto& idx = s.meshes[0].indices;
  EXPECT_EQ(std::vector<uint32_t>(idx.begin(), idx.end()),
            (std::vector<uint32_t>{0, 1, 2, 0, 2, 3, 0, 1, 4}));
}

TEST(Obj, MissingFileNamesTheFile) {
  const Error e = error_of([] { load_scene("/nonexistent/dir/scene.obj"); });
  EXPECT_EQ(e.code(), ErrorCode::file_not_found);
  expect_mentions(e, "/nonexistent/dir/scene.obj");
}

TEST(Obj, MalformedLinesNameFileAndLine) {
  const std::string bad_vertex =
      test::write_temp_file("bad_vertex.obj", "v 0 0 0\nv 1 0 0\nv 1 abc 0\nf 1 2 3\n");
  Error e = error_of([&] { load_scene(bad_vertex); });
  EXPECT_EQ(e.code(), ErrorCode::parse_error);
  expect_mentions(e, bad_vertex + ":3");
  const std::string short_face =
      test::write_temp_file("short_face.obj", "v 0 0 0\nv 1 0 0\nv 1 1 0\n\nf 1 2\n");
  e = error_of([&] { load_scene(short_face); });
  expect_mentions(e, short_face + ":5");
  const std::string zero_index =
      test::write_temp_file("zero_index.obj", "v 0 0 0\nv 1 0 0\nv 1 1 0\nf 0 1 2\n");
  expect_mentions(error_of([&] { load_scene(zero_index); }), zero_index + ":4");
  // Truncated in the middle of a vertex line.
  const std::string truncated = test::write_temp_file("truncated.obj", "v 0 0 0\nv 1 0 0\nv 1 1");
  expect_mentions(error_of([&] { load_scene(truncated); }), truncated + ":3");
}

TEST(Obj, BadTrianglesAreCountedAndSkipped) {
  const std::string path = test::write_temp_file("bad_tris.obj",
                                                 "v 0 0 0\nv 1 0 0\nv 0 1 0\nv nan 0 0\nv 2 0 0\n"
                                                 "f 1 2 3\n"    // good
                                                 "f 1 2 4\n"    // NaN vertex
                                                 "f 1 2 9\n"    // index past the end
                                                 "f 1 2 5\n"    // collinear: zero area
                                                 "f 1 1 3\n"    // repeated vertex
                                                 "f 2 3 1\n");  // good
  const Scene s = load_scene(path);
  const SceneValidation v = validate_scene(s);
  EXPECT_EQ(v.report.triangle_count, 6u);
  EXPECT_EQ(v.report.valid_triangle_count, 2u);
  EXPECT_EQ(v.report.nonfinite_triangle_count, 1u);
  EXPECT_EQ(v.report.bad_index_triangle_count, 1u);
  EXPECT_EQ(v.report.degenerate_triangle_count, 2u);
  // Valid triangles keep their file ids; the BVH never sees the others.
  const Accel accel = build_accel(s, BuildConfig{});
  EXPECT_EQ(accel.prim_count, 2u);
  const Hit h = intersect(accel, Ray{{0.2f, 0.2f, 1}, {0, 0, -1}});
  ASSERT_TRUE(h.hit());
  EXPECT_EQ(h.prim_id, 0u);  // 0 and 5 are the same triangle: equal t, the smaller id wins
}

TEST(Scene, EmptyMeshesAndScenesAreReported) {
  Scene s;
  s.meshes.resize(2);
  const SceneValidation v = validate_scene(s);
  EXPECT_EQ(v.report.empty_mesh_count, 2u);
  EXPECT_EQ(v.report.valid_triangle_count, 0u);
  const std::string empty = test::write_temp_file("empty.obj", "# nothing here\n");
  EXPECT_EQ(load_scene(empty).triangle_count(), 0u);
}

TEST(Scene, UnknownFormatAndBuiltins) {
  const std::string path = test::write_temp_file("scene.xyz", "hello");
  EXPECT_EQ(error_of([&] { load_scene(path); }).code(), ErrorCode::unsupported);
  EXPECT_EQ(error_of([] { load_scene("builtin:nope"); }).code(), ErrorCode::invalid_argument);
  EXPECT_EQ(load_scene("builtin:cornell_box").triangle_count(), 32u);
}

// The procedural built-ins the trace benchmark runs: documented sizes, every triangle valid,
// inside their documented extents, and the same triangles on every load (fixed seeds).
TEST(Scene, ProceduralBuiltinsAreValidAndRepeatable) {
  struct Expect {
    const char* name;
    size_t triangles;
    Vec3 lo, hi;
  };
  for (const Expect& e : {Expect{"soup", 400000, {-0.6f, -0.6f, -0.6f}, {10.6f, 10.6f, 10.6f}},
                          Expect{"hairball", 720000, {-2, -2, -2}, {2, 2, 2}},
                          Expect{"terrain", 522242, {0, 0, 0}, {100, 40, 100}},
                          Expect{"sphere_field", 528002, {-2, -0.01f, -2}, {102, 4.1f, 102}}}) {
    SCOPED_TRACE(e.name);
    const Scene a = load_scene(std::string("builtin:") + e.name);
    ASSERT_EQ(a.triangle_count(), e.triangles);
    EXPECT_EQ(validate_scene(a).report.valid_triangle_count, e.triangles);
    const Bounds3 b = scene_bounds(a);
    const float lo[3] = {b.lo.x, b.lo.y, b.lo.z}, hi[3] = {b.hi.x, b.hi.y, b.hi.z};
    const float want_lo[3] = {e.lo.x, e.lo.y, e.lo.z}, want_hi[3] = {e.hi.x, e.hi.y, e.hi.z};
    for (int k = 0; k < 3; ++k) {
      EXPECT_GE(lo[k], want_lo[k]) << "axis " << k;
      EXPECT_LE(hi[k], want_hi[k]) << "axis " << k;
      EXPECT_GT(hi[k] - lo[k], 0.1f * (want_hi[k] - want_lo[k])) << "axis " << k;
    }
    const Scene again = load_scene(std::string("builtin:") + e.name);
    ASSERT_EQ(again.meshes[0].positions.size(), a.meshes[0].positions.size());
    EXPECT_EQ(0, std::memcmp(again.meshes[0].positions.data(), a.meshes[0].positions.data(),
                             a.meshes[0].positions.size() * sizeof(Vec3)));
    EXPECT_EQ(again.meshes[0].indices, a.meshes[0].indices);
  }
  const std::vector<std::string> names = builtin_scene_names();
  for (const char* n : {"cornell_box", "lamp_hall", "soup", "hairball", "terrain", "sphere_field"})
    EXPECT_NE(std::find(names.begin(), names.end(), n), names.end()) << n;
}

// KHR_materials_specular sets the dielectric coat's weight: specularFactor times the brightest
// channel of specularColorFactor, clamped to [0, 1]; without it a glTF dielectric has the full
// coat. (scripts/denoise/gltf_scene.py writes the MTL's Ks this way; families_smoke.sh renders
// both files and asks for the same frames.)
TEST(Gltf, SpecularExtensionSetsTheCoatWeight) {
  const std::string path = one_triangle_gltf("specular.gltf", R"([
      {"name": "plain"},
      {"name": "lambert", "extensions": {"KHR_materials_specular": {"specularFactor": 0}}},
      {"name": "tinted", "extensions": {"KHR_materials_specular":
          {"specularFactor": 0.5, "specularColorFactor": [0.2, 0.8, 0.4]}}},
      {"name": "loud", "extensions": {"KHR_materials_specular": {"specularFactor": 3}}},
      {"name": "default_factor", "extensions": {"KHR_materials_specular": {}}}]
)",
                                             R"("extensionsUsed": ["KHR_materials_specular"],)");
  const Scene s = load_scene(path);
  ASSERT_GE(s.materials.size(), 5u);
  EXPECT_EQ(s.materials[0].specular, 1.0f);
  EXPECT_EQ(s.materials[1].specular, 0.0f);
  EXPECT_FLOAT_EQ(s.materials[2].specular, 0.4f);
  EXPECT_EQ(s.materials[3].specular, 1.0f);
  EXPECT_EQ(s.materials[4].specular, 1.0f);
}

// Cut-out opacity: glTF's alphaMode, alphaCutoff and baseColorFactor's fourth value (with the
// base colour texture's A channel); MTL's d (or Tr) and map_d (a mask: its A channel, or its
// grey level when the image has no alpha).
TEST(Gltf, AlphaModesAreRead) {
  const std::string path = one_triangle_gltf("alpha.gltf", R"([
      {"name": "plain", "pbrMetallicRoughness": {"baseColorFactor": [1, 1, 1, 0.3]}},
      {"name": "leaf", "alphaMode": "MASK", "alphaCutoff": 0.25},
      {"name": "glass", "alphaMode": "BLEND",
       "pbrMetallicRoughness": {"baseColorFactor": [1, 1, 1, 0.3]}}]
)");
  const Scene s = load_scene(path);
  ASSERT_GE(s.materials.size(), 3u);
  EXPECT_EQ(s.materials[0].alpha_mode, Material::AlphaMode::opaque);  // OPAQUE ignores alpha
  EXPECT_EQ(s.materials[1].alpha_mode, Material::AlphaMode::mask);
  EXPECT_FLOAT_EQ(s.materials[1].alpha_cutoff, 0.25f);
  EXPECT_FLOAT_EQ(s.materials[1].alpha, 1.0f);
  EXPECT_EQ(s.materials[2].alpha_mode, Material::AlphaMode::blend);
  EXPECT_FLOAT_EQ(s.materials[2].alpha, 0.3f);
}

// Glass: KHR_materials_transmission's factor, KHR_materials_ior (0: the extension's F0 = 1),
// KHR_materials_volume (a thickness makes a refracting solid with its attenuation; none, a thin
// sheet); required, they load. MTL: illum 4, 6, 7 and 9 with Ni and Tf.
TEST(Gltf, TransmissionIorAndVolumeAreRead) {
  const std::string path = one_triangle_gltf("glass.gltf", R"([
      {"name": "pane", "extensions": {"KHR_materials_transmission": {"transmissionFactor": 0.9}}},
      {"name": "water", "extensions": {"KHR_materials_transmission": {"transmissionFactor": 1},
          "KHR_materials_ior": {"ior": 1.33},
          "KHR_materials_volume": {"thicknessFactor": 0.5, "attenuationDistance": 2,
                                   "attenuationColor": [0.5, 0.9, 1]}}},
      {"name": "mirror_ior", "extensions": {"KHR_materials_ior": {"ior": 0}}},
      {"name": "loud", "extensions": {"KHR_materials_transmission": {"transmissionFactor": 4}}}]
)",
                                             R"("extensionsRequired": ["KHR_materials_transmission",
        "KHR_materials_ior", "KHR_materials_volume"],
    "extensionsUsed": ["KHR_materials_transmission", "KHR_materials_ior", "KHR_materials_volume"],)");
  const Scene s = load_scene(path);
  ASSERT_GE(s.materials.size(), 4u);
  EXPECT_FLOAT_EQ(s.materials[0].transmission, 0.9f);
  EXPECT_TRUE(s.materials[0].thin_walled);
  EXPECT_FLOAT_EQ(s.materials[0].ior, 1.5f);
  EXPECT_EQ(s.materials[1].transmission, 1.0f);
  EXPECT_FALSE(s.materials[1].thin_walled);
  EXPECT_FLOAT_EQ(s.materials[1].ior, 1.33f);
  EXPECT_FLOAT_EQ(s.materials[1].attenuation_distance, 2.0f);
  EXPECT_FLOAT_EQ(s.materials[1].attenuation_color.x, 0.5f);
  EXPECT_EQ(s.materials[2].transmission, 0.0f);
  EXPECT_GT(s.materials[2].ior, 1000.0f);
  EXPECT_EQ(s.materials[3].transmission, 1.0f);
}

TEST(Obj, GlassIllumModelsAreRead) {
  const std::filesystem::path dir = test::test_temp_dir();
  std::ofstream(dir / "glass.mtl")
      << "newmtl plastic\nKd 1 1 1\nillum 2\nNi 1.4\n"
         "newmtl window\nKd 0 0 0\nillum 4\nd 0.2\n"
         "newmtl bottle\nKd 0.1 0.1 0.1\nTf 0.6 0.9 0.7\nNi 1.52\nillum 7\n";
  std::ofstream(dir / "glass.obj") << "mtllib glass.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\n"
                                      "usemtl plastic\nf 1 2 3\nusemtl window\nf 1 2 3\n"
                                      "usemtl bottle\nf 1 2 3\n";
  const Scene s = load_scene((dir / "glass.obj").string());
  ASSERT_GE(s.materials.size(), 3u);
  EXPECT_EQ(s.materials[0].transmission, 0.0f);
  EXPECT_EQ(s.materials[1].transmission, 1.0f);
  EXPECT_FLOAT_EQ(s.materials[1].ior, 1.5f);  // no Ni
  EXPECT_EQ(s.materials[1].alpha_mode,
            Material::AlphaMode::opaque);              // the glass is the transparency
  EXPECT_FLOAT_EQ(s.materials[1].base_color.y, 1.0f);  // no Tf: clear
  EXPECT_EQ(s.materials[1].roughness, 0.0f);           // no Ns or Pr: polished
  EXPECT_FLOAT_EQ(s.materials[2].ior, 1.52f);
  EXPECT_FLOAT_EQ(s.materials[2].base_color.y, 0.9f);
}

TEST(Obj, DissolveAndAlphaMapsAreRead) {
  const std::filesystem::path dir = test::test_temp_dir();
  // 2 x 2 uncompressed true-colour TGAs: 24 bits (no alpha: the mask is its grey level) and
  // 32 bits (its A channel).
  auto tga = [&](const char* name, int bits) {
    std::string bytes(18, '\0');
    bytes[2] = 2, bytes[12] = 2, bytes[14] = 2, bytes[16] = char(bits), bytes[17] = 0x20;
    for (int i = 0; i < 4; ++i) {
      const char v = i % 2 ? char(255) : 0;
      bytes += std::string(3, v);
      if (bits == 32) bytes += i == 0 ? char(0) : char(255);
    }
    std::ofstream(dir / name, std::ios::binary) << bytes;
  };
  tga("alpha_grey.tga", 24);
  tga("alpha_cut.tga", 32);
  std::ofstream(dir / "alpha.mtl") << "newmtl solid\nKd 1 1 1\n"
                                      "newmtl glass\nKd 1 1 1\nd 0.4\n"
                                      "newmtl tinted\nKd 1 1 1\nTr 0.75\n"
                                      "newmtl leaf\nKd 1 1 1\nmap_d alpha_grey.tga\n"
                                      "newmtl fence\nKd 1 1 1\nmap_d alpha_cut.tga\n";
  std::ofstream(dir / "alpha.obj") << "mtllib alpha.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\n"
                                      "usemtl solid\nf 1 2 3\nusemtl glass\nf 1 2 3\n"
                                      "usemtl tinted\nf 1 2 3\nusemtl leaf\nf 1 2 3\n"
                                      "usemtl fence\nf 1 2 3\n";
  const Scene s = load_scene((dir / "alpha.obj").string());
  auto named = [&](const std::string& name) {
    for (const Material& m : s.materials)
      if (m.name == name) return m;
    ADD_FAILURE() << name;
    return Material{};
  };
  EXPECT_EQ(named("solid").alpha_mode, Material::AlphaMode::opaque);
  EXPECT_EQ(named("glass").alpha_mode, Material::AlphaMode::blend);
  EXPECT_FLOAT_EQ(named("glass").alpha, 0.4f);
  EXPECT_EQ(named("tinted").alpha_mode, Material::AlphaMode::blend);
  EXPECT_FLOAT_EQ(named("tinted").alpha, 0.25f);
  EXPECT_EQ(named("leaf").alpha_mode, Material::AlphaMode::mask);
  EXPECT_GE(named("leaf").alpha_texture, 0);
  EXPECT_TRUE(named("leaf").alpha_from_red);
  EXPECT_EQ(named("fence").alpha_mode, Material::AlphaMode::mask);
  EXPECT_FALSE(named("fence").alpha_from_red);
}

// KHR_texture_transform moves the coordinates themselves (uv' = offset + R (scale uv), the
// extension's matrix); a primitive without TEXCOORD_0 gets (0, 0) instead of stripping the
// coordinates of the mesh's other primitives. Both loaders (flattened and two-level).
TEST(Gltf, TextureTransformsAndMissingCoordinates) {
  std::string bytes;
  auto put = [&](std::initializer_list<float> v) {
    for (float x : v) bytes.append(reinterpret_cast<const char*>(&x), sizeof x);
  };
  put({0, 0, 0, 1, 0, 0, 0, 1, 0});  // positions (36 bytes)
  put({0, 0, 1, 0, 0, 1});           // uvs (24 bytes)
  const std::string path =
      test::write_temp_file("texture_transform.gltf", fmt::format(R"({{
    "asset": {{"version": "2.0"}}, "scene": 0, "scenes": [{{"nodes": [0]}}], "nodes": [{{"mesh": 0}}],
    "extensionsUsed": ["KHR_texture_transform"], "extensionsRequired": ["KHR_texture_transform"],
    "meshes": [{{"primitives": [
      {{"attributes": {{"POSITION": 0, "TEXCOORD_0": 1}}, "material": 0}},
      {{"attributes": {{"POSITION": 0}}, "material": 1}}]}}],
    "materials": [
      {{"name": "moved", "pbrMetallicRoughness": {{"baseColorTexture": {{"index": 0,
        "extensions": {{"KHR_texture_transform":
          {{"offset": [0.5, 0.25], "scale": [2, 3], "rotation": 1.5707963267948966}}}}}}}}}},
      {{"name": "plain"}}],
    "textures": [{{"source": 0}}],
    "images": [{{"uri": "missing.png"}}],
    "buffers": [{{"byteLength": 60, "uri": "data:application/octet-stream;base64,{}"}}],
    "bufferViews": [{{"buffer": 0, "byteOffset": 0, "byteLength": 36}},
                    {{"buffer": 0, "byteOffset": 36, "byteLength": 24}}],
    "accessors": [{{"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3",
                   "min": [0, 0, 0], "max": [1, 1, 0]}},
                  {{"bufferView": 1, "componentType": 5126, "count": 3, "type": "VEC2"}}]}})",
                                                                  test::base64(bytes)));
  // (u, v) -> (0.5 - 3 v, 0.25 + 2 u): rotation by 90 degrees after the scale.
  const Vec2 want[6] = {{0.5f, 0.25f}, {0.5f, 2.25f}, {-2.5f, 0.25f}, {0, 0}, {0, 0}, {0, 0}};
  auto check = [&](const std::vector<Vec2>& uvs, const char* which) {
    ASSERT_EQ(uvs.size(), 6u) << which;
    for (int i = 0; i < 6; ++i) {
      EXPECT_NEAR(uvs[size_t(i)].x, want[i].x, 1e-6f) << which << " " << i;
      EXPECT_NEAR(uvs[size_t(i)].y, want[i].y, 1e-6f) << which << " " << i;
    }
  };
  const Scene s = load_scene(path);
  ASSERT_EQ(s.meshes.size(), 1u);
  check(s.meshes[0].uvs, "flattened");
  const Asset a = Asset::load(path);
  check(a.scene().mesh(a.scene().instance_mesh(0)).uvs, "two-level");
}

// The coordinate set the material's textures name (texCoord): TEXCOORD_1 here, not 0.
TEST(Gltf, TexturesReadTheCoordinateSetTheyName) {
  std::string bytes;
  auto put = [&](std::initializer_list<float> v) {
    for (float x : v) bytes.append(reinterpret_cast<const char*>(&x), sizeof x);
  };
  put({0, 0, 0, 1, 0, 0, 0, 1, 0});           // positions
  put({9, 9, 9, 9, 9, 9});                    // TEXCOORD_0
  put({0.25f, 0.5f, 0.75f, 0.5f, 0.25f, 1});  // TEXCOORD_1
  const std::string path =
      test::write_temp_file("texcoord_set.gltf", fmt::format(R"({{
    "asset": {{"version": "2.0"}}, "scene": 0, "scenes": [{{"nodes": [0]}}], "nodes": [{{"mesh": 0}}],
    "meshes": [{{"primitives": [{{"attributes": {{"POSITION": 0, "TEXCOORD_0": 1, "TEXCOORD_1": 2}},
                                  "material": 0}}]}}],
    "materials": [{{"pbrMetallicRoughness": {{"baseColorTexture": {{"index": 0, "texCoord": 1}}}}}}],
    "textures": [{{"source": 0}}], "images": [{{"uri": "missing.png"}}],
    "buffers": [{{"byteLength": 84, "uri": "data:application/octet-stream;base64,{}"}}],
    "bufferViews": [{{"buffer": 0, "byteOffset": 0, "byteLength": 36}},
                    {{"buffer": 0, "byteOffset": 36, "byteLength": 24}},
                    {{"buffer": 0, "byteOffset": 60, "byteLength": 24}}],
    "accessors": [{{"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3",
                   "min": [0, 0, 0], "max": [1, 1, 0]}},
                  {{"bufferView": 1, "componentType": 5126, "count": 3, "type": "VEC2"}},
                  {{"bufferView": 2, "componentType": 5126, "count": 3, "type": "VEC2"}}]}})",
                                                             test::base64(bytes)));
  const Scene s = load_scene(path);
  ASSERT_EQ(s.meshes.size(), 1u);
  ASSERT_EQ(s.meshes[0].uvs.size(), 3u);
  EXPECT_EQ(s.meshes[0].uvs[0].x, 0.25f);
  EXPECT_EQ(s.meshes[0].uvs[2].y, 1.0f);
}

TEST(Gltf, MalformedAndTruncatedFilesAreErrors) {
  const std::string not_json =
      test::write_temp_file("broken.gltf", "{ \"asset\": { \"version\": \"2.0\" ");
  Error e = error_of([&] { load_scene(not_json); });
  EXPECT_EQ(e.code(), ErrorCode::parse_error);
  expect_mentions(e, not_json);
  // A valid header whose buffer is shorter than its accessors claim.
  const std::string short_buffer = test::write_temp_file("short.gltf", R"({
    "asset": {"version": "2.0"}, "scene": 0, "scenes": [{"nodes": [0]}], "nodes": [{"mesh": 0}],
    "meshes": [{"primitives": [{"attributes": {"POSITION": 0}}]}],
    "buffers": [{"byteLength": 12, "uri": "data:application/octet-stream;base64,AAAAAAAAAAAAAAAA"}],
    "bufferViews": [{"buffer": 0, "byteOffset": 0, "byteLength": 12}],
    "accessors": [{"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3"}]})");
  e = error_of([&] { load_scene(short_buffer); });
  EXPECT_EQ(e.code(), ErrorCode::parse_error);
  expect_mentions(e, short_buffer);
  // A truncated binary glTF.
  if (auto fox = test::shared_scene("gltf_fox/Fox.glb")) {
    std::ifstream in(*fox, std::ios::binary);
    std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    const std::string cut = test::write_temp_file("cut.glb", bytes.substr(0, bytes.size() / 2));
    e = error_of([&] { load_scene(cut); });
    expect_mentions(e, cut);
  }
}

TEST(RaysFiles, RoundTripAndCorruption) {
  std::vector<Ray> rays = test::random_rays(100, 4);
  const std::string path = test::write_temp_file("a.rays", "");
  write_rays(path, rays);
  const std::vector<Ray> back = read_rays(path);
  ASSERT_EQ(back.size(), rays.size());
  for (size_t i = 0; i < rays.size(); ++i) {
    EXPECT_EQ(back[i].org.x, rays[i].org.x);
    EXPECT_EQ(back[i].dir.z, rays[i].dir.z);
    EXPECT_EQ(back[i].tmax, rays[i].tmax);
  }
  std::vector<Hit> hits(3);
  hits[1] = Hit{2.5f, 7};
  const std::string hpath = test::write_temp_file("a.hits", "");
  write_hits(hpath, hits);
  const auto hback = read_hits(hpath);
  ASSERT_EQ(hback.size(), 3u);
  EXPECT_TRUE(std::isinf(hback[0].t));
  EXPECT_EQ(hback[0].prim_id, invalid_id);
  EXPECT_EQ(hback[1].prim_id, 7u);
  EXPECT_EQ(hback[1].t, 2.5f);
  // Truncated: the header promises 100 rays.
  std::ifstream in(path, std::ios::binary);
  std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  const std::string cut = test::write_temp_file("cut.rays", bytes.substr(0, bytes.size() - 5));
  Error e = error_of([&] { read_rays(cut); });
  EXPECT_EQ(e.code(), ErrorCode::parse_error);
  expect_mentions(e, cut);
  const std::string wrong =
      test::write_temp_file("wrong.rays", std::string("HITS\x01\0\0\0", 8) + std::string(8, '\0'));
  expect_mentions(error_of([&] { read_rays(wrong); }), "magic");
  EXPECT_EQ(error_of([&] { read_rays("/nonexistent.rays"); }).code(), ErrorCode::file_not_found);
}

}  // namespace
}  // namespace kestrel
