// Vertex colours: glTF COLOR_0 (normalised bytes, floats) and OBJ "v x y z r g b" (sRGB) as
// loaded (and glTF's quantised attributes, read by the same accessor code), and in the renderer the
// base colour times the colour interpolated at the hit (the albedo AOV against the linear gradient
// written on a quad's corners).
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>

#include "kestrel/kestrel.h"
#include "support/oracles.h"
#include "support/scene_renderer.h"

namespace kestrel {
namespace {

TEST(VertexColors, GltfColor0IsRead) {
  // One triangle; COLOR_0 as normalised unsigned bytes, VEC4 (red, green, half blue).
  const std::string path = test::write_temp_file("colors.gltf", R"({
    "asset": {"version": "2.0"}, "scene": 0, "scenes": [{"nodes": [0]}], "nodes": [{"mesh": 0}],
    "meshes": [{"primitives": [{"attributes": {"POSITION": 0, "COLOR_0": 1}}]}],
    "buffers": [{"byteLength": 48,
                 "uri": "data:application/octet-stream;base64,AAAAAAAAAAAAAAAAAACAPwAAAAAAAAAAAAAAAAAAgD8AAAAA/wAA/wD/AP8AAID/"}],
    "bufferViews": [{"buffer": 0, "byteOffset": 0, "byteLength": 36},
                    {"buffer": 0, "byteOffset": 36, "byteLength": 12}],
    "accessors": [{"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3",
                   "min": [0, 0, 0], "max": [1, 1, 0]},
                  {"bufferView": 1, "componentType": 5121, "normalized": true, "count": 3,
                   "type": "VEC4"}]})");
  for (const bool instanced : {false, true}) {
    const Scene s = instanced ? Asset::load(path).scene().flatten() : load_scene(path);
    ASSERT_EQ(s.meshes.size(), 1u);
    const TriangleMesh& m = s.meshes[0];
    ASSERT_EQ(m.colors.size(), 3u) << instanced;
    EXPECT_EQ(m.colors[0].x, 1.0f);
    EXPECT_EQ(m.colors[0].y, 0.0f);
    EXPECT_EQ(m.colors[1].y, 1.0f);
    EXPECT_NEAR(m.colors[2].z, 128.0f / 255.0f, 1e-6f);
  }
}

// KHR_mesh_quantization (what gltfpack writes): positions as unnormalised shorts (stride 8),
// normals as normalised bytes; a file that requires it loads.
TEST(VertexColors, QuantizedGltfAttributesAreRead) {
  const std::string path = test::write_temp_file("quantized.gltf", R"({
    "asset": {"version": "2.0"}, "scene": 0, "scenes": [{"nodes": [0]}], "nodes": [{"mesh": 0}],
    "extensionsUsed": ["KHR_mesh_quantization"], "extensionsRequired": ["KHR_mesh_quantization"],
    "meshes": [{"primitives": [{"attributes": {"POSITION": 0, "NORMAL": 1}}]}],
    "buffers": [{"byteLength": 36,
                 "uri": "data:application/octet-stream;base64,AAAAAAAAAABkAAAAAAAAAAAAOP8AAAAAAAB/AAAAgQAAfwAA"}],
    "bufferViews": [{"buffer": 0, "byteOffset": 0, "byteLength": 24, "byteStride": 8},
                    {"buffer": 0, "byteOffset": 24, "byteLength": 12, "byteStride": 4}],
    "accessors": [{"bufferView": 0, "componentType": 5122, "count": 3, "type": "VEC3",
                   "min": [0, -200, 0], "max": [100, 0, 0]},
                  {"bufferView": 1, "componentType": 5120, "normalized": true, "count": 3,
                   "type": "VEC3"}]})");
  for (const bool instanced : {false, true}) {
    const Scene s = instanced ? Asset::load(path).scene().flatten() : load_scene(path);
    ASSERT_EQ(s.meshes.size(), 1u);
    const TriangleMesh& m = s.meshes[0];
    ASSERT_EQ(m.positions.size(), 3u);
    EXPECT_EQ(m.positions[1].x, 100.0f);
    EXPECT_EQ(m.positions[2].y, -200.0f);
    ASSERT_EQ(m.normals.size(), 3u) << instanced;
    EXPECT_EQ(m.normals[0].z, 1.0f);
    EXPECT_EQ(m.normals[1].z, -1.0f);
    EXPECT_EQ(m.normals[2].y, 1.0f);
  }
}

TEST(VertexColors, ObjVertexColorsAreDecodedFromSrgb) {
  const std::filesystem::path dir = test::test_temp_dir();
  std::ofstream(dir / "colors.obj") << "v 0 0 0 1 0 0.5\nv 1 0 0 0 1 0\nv 0 1 0 0 0 1\nf 1 2 3\n";
  std::ofstream(dir / "some_colors.obj") << "v 0 0 0 1 0 0.5\nv 1 0 0\nv 0 1 0\nf 1 2 3\n";
  const Scene s = load_scene((dir / "colors.obj").string());
  ASSERT_EQ(s.meshes[0].colors.size(), 3u);
  EXPECT_EQ(s.meshes[0].colors[0].x, 1.0f);
  EXPECT_NEAR(s.meshes[0].colors[0].z, 0.2140411f, 1e-6f);  // sRGB 0.5
  // Colours on some vertices only: none (tinyobj keeps colours given for every vertex).
  EXPECT_TRUE(load_scene((dir / "some_colors.obj").string()).meshes[0].colors.empty());
}

TEST(VertexColors, AlbedoIsBaseTimesTheInterpolatedColour) {
  // A quad in the plane y = 0 from x = -1 to 1: red on its x = -1 edge, green on x = 1 (a
  // linear function of x, so any triangulation interpolates it exactly); base colour 0.5.
  Scene s;
  s.source = "test:vertex_colors";
  s.materials = {Material{.name = "grey", .base_color = {0.5f, 0.5f, 0.5f}}};
  TriangleMesh m;
  m.positions = {{-1, 0, -1}, {1, 0, -1}, {1, 0, 1}, {-1, 0, 1}};
  m.colors = {{1, 0, 0}, {0, 1, 0}, {0, 1, 0}, {1, 0, 0}};
  m.indices = {0, 2, 1, 0, 3, 2};
  m.material_ids = {0, 0};
  s.meshes.push_back(m);
  test::SceneRenderer r(std::move(s), Environment::parse("sky"));
  RenderSettings rs;
  rs.width = 8, rs.height = 1, rs.spp = 1, rs.max_depth = 1, rs.jitter = false;
  // Looking straight down at the strip z = 0 (the camera's right is +x).
  const Frame f = r.render(Camera{{0, 10, 0.001f}, {0, 0, 0}, 1}, rs);
  const float half_width = 10 * std::tan(0.5f * 3.14159265f / 180) * 8;  // 0.7 at the plane
  for (int x = 0; x < 8; ++x) {
    const float wx = (2 * (x + 0.5f) / 8 - 1) * half_width;  // the pixel's world x
    const float green = (wx + 1) / 2;
    const float* a = f[Aov::albedo].at(x, 0);
    EXPECT_NEAR(a[0], 0.5f * (1 - green), 2e-3f) << "pixel " << x;
    EXPECT_NEAR(a[1], 0.5f * green, 2e-3f) << "pixel " << x;
    EXPECT_NEAR(a[2], 0.0f, 1e-6f);
  }
}

}  // namespace
}  // namespace kestrel
