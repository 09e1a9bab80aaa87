#include "support/oracles.h"

#include <fmt/format.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <map>

#include <unistd.h>

#include "core/vec.h"
#include "geometry/prim_ref.h"

namespace kestrel::test {

uint64_t Rng::next() {
  uint64_t z = (state += 0x9E3779B97F4A7C15ull);
  z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
  z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
  return z ^ (z >> 31);
}
float Rng::uniform() {
  return float(next() >> 40) * (1.0f / 16777216.0f);
}
float Rng::uniform(float lo, float hi) {
  return lo + (hi - lo) * uniform();
}
Vec3 Rng::in_box(Vec3 lo, Vec3 hi) {
  return {uniform(lo.x, hi.x), uniform(lo.y, hi.y), uniform(lo.z, hi.z)};
}
Vec3 Rng::on_sphere() {
  const float z = uniform(-1.0f, 1.0f), phi = uniform(0.0f, 6.2831853f);
  const float r = std::sqrt(std::max(0.0f, 1.0f - z * z));
  return {r * std::cos(phi), r * std::sin(phi), z};
}

Scene random_soup(size_t n, float size, uint64_t seed) {
  Rng rng{seed};
  Scene scene;
  scene.source = "test:soup";
  TriangleMesh mesh;
  for (size_t i = 0; i < n; ++i) {
    const Vec3 a = rng.in_box({0, 0, 0}, {1, 1, 1});
    for (int k = 0; k < 3; ++k) {
      mesh.positions.push_back(k == 0 ? a : a + rng.on_sphere() * rng.uniform(0.05f * size, size));
      mesh.indices.push_back(uint32_t(mesh.positions.size() - 1));
    }
    mesh.material_ids.push_back(0);
  }
  scene.meshes.push_back(std::move(mesh));
  scene.materials.push_back(Material{});
  return scene;
}

Scene soup_with_far_triangles(size_t n, size_t far, uint64_t seed) {
  Scene scene = random_soup(n, 0.1f, seed);
  TriangleMesh& mesh = scene.meshes[0];
  const float big = 3e38f;
  for (size_t i = 0; i < far; ++i) {
    const uint32_t base = uint32_t(mesh.positions.size());
    const float z = float(i) * 1e36f;
    if (i % 2) {
      mesh.positions.insert(mesh.positions.end(),
                            {{-big, -big, z}, {big, -big, z + 1e37f}, {0, big, -z}});
    } else {
      mesh.positions.insert(mesh.positions.end(),
                            {{big, big, big - z}, {3.3e38f, big, big}, {big, 3.3e38f, big}});
    }
    mesh.indices.insert(mesh.indices.end(), {base, base + 1, base + 2});
  }
  return scene;
}

Scene closed_sphere(int subdivisions, Vec3 c, float radius) {
  const float t = (1.0f + std::sqrt(5.0f)) / 2.0f;
  std::vector<Vec3> v = {{-1, t, 0},  {1, t, 0},  {-1, -t, 0}, {1, -t, 0}, {0, -1, t},  {0, 1, t},
                         {0, -1, -t}, {0, 1, -t}, {t, 0, -1},  {t, 0, 1},  {-t, 0, -1}, {-t, 0, 1}};
  for (Vec3& p : v) p = normalize(p);
  std::vector<uint32_t> f = {0, 11, 5,  0, 5,  1, 0, 1, 7, 0, 7,  10, 0, 10, 11, 1, 5, 9, 5, 11,
                             4, 11, 10, 2, 10, 7, 6, 7, 1, 8, 3,  9,  4, 3,  4,  2, 3, 2, 6, 3,
                             6, 8,  3,  8, 9,  4, 9, 5, 2, 4, 11, 6,  2, 10, 8,  6, 7, 9, 8, 1};
  for (int s = 0; s < subdivisions; ++s) {
    std::map<std::pair<uint32_t, uint32_t>, uint32_t> mid;
    auto midpoint = [&](uint32_t a, uint32_t b) {
      auto key = std::minmax(a, b);
      auto it = mid.find(key);
      if (it != mid.end()) return it->second;
      v.push_back(normalize(v[a] + v[b]));
      return mid[key] = uint32_t(v.size() - 1);
    };
    std::vector<uint32_t> g;
    for (size_t i = 0; i < f.size(); i += 3) {
      const uint32_t a = f[i], b = f[i + 1], cc = f[i + 2];
      const uint32_t ab = midpoint(a, b), bc = midpoint(b, cc), ca = midpoint(cc, a);
      g.insert(g.end(), {a, ab, ca, b, bc, ab, cc, ca, bc, ab, bc, ca});
    }
    f.swap(g);
  }
  Scene scene;
  scene.source = "test:sphere";
  TriangleMesh mesh;
  for (const Vec3& p : v) mesh.positions.push_back(c + p * radius);
  mesh.indices = f;
  mesh.material_ids.assign(f.size() / 3, 0);
  scene.meshes.push_back(std::move(mesh));
  scene.materials.push_back(Material{});
  return scene;
}

Scene lit_plane(float albedo, const std::string& source) {
  Scene s;
  s.source = source;
  s.materials = {Material{.name = "white", .base_color = {albedo, albedo, albedo}}};
  TriangleMesh m;
  m.positions = {{-20, -20, -5}, {20, -20, -5}, {20, 20, -5}, {-20, 20, -5}};
  m.indices = {0, 1, 2, 0, 2, 3};
  m.material_ids = {0, 0};
  s.meshes.push_back(m);
  return s;
}

Scene closed_box(Vec3 lo, Vec3 hi) {
  Scene scene;
  scene.source = "test:box";
  TriangleMesh mesh;
  for (int i = 0; i < 8; ++i)
    mesh.positions.push_back({i & 1 ? hi.x : lo.x, i & 2 ? hi.y : lo.y, i & 4 ? hi.z : lo.z});
  mesh.indices = {0, 2, 1, 1, 2, 3, 4, 5, 6, 5, 7, 6, 0, 1, 4, 1, 5, 4,
                  2, 6, 3, 3, 6, 7, 0, 4, 2, 2, 4, 6, 1, 3, 5, 3, 7, 5};
  mesh.material_ids.assign(12, 0);
  scene.meshes.push_back(std::move(mesh));
  scene.materials.push_back(Material{});
  return scene;
}

std::vector<Ray> random_rays(size_t n, uint64_t seed) {
  Rng rng{seed};
  std::vector<Ray> rays(n);
  for (size_t i = 0; i < n; ++i) {
    Ray& r = rays[i];
    r.org = rng.in_box({-0.5f, -0.5f, -0.5f}, {1.5f, 1.5f, 1.5f});
    r.dir = rng.in_box({0, 0, 0}, {1, 1, 1}) - r.org;
    switch (i % 8) {
      case 1:
        r.dir.x = 0;
        break;  // parallel to the yz plane
      case 2:
        r.dir.y = r.dir.z = 0;
        break;  // along x
      case 3:
        r.tmax = rng.uniform(0.2f, 1.0f);
        break;
      case 4:
        r.tmin = rng.uniform(0.1f, 0.6f);
        break;
      default:
        break;
    }
    if (r.dir.x == 0 && r.dir.y == 0 && r.dir.z == 0) r.dir = {0, 0, 1};
  }
  return rays;
}

std::optional<std::string> shared_scene(const std::string& rel) {
  const std::string p = std::string(KESTREL_SCENE_ROOT) + "/" + rel;
  if (std::filesystem::exists(p)) return p;
  return std::nullopt;
}

Soup flatten(const Scene& scene) {
  Soup soup;
  const SceneValidation v = validate_scene(scene);
  soup.triangles = gather_triangles(scene, v);
  soup.valid = v.valid;
  return soup;
}

std::vector<Builder> all_builders() {
  return {Builder::median, Builder::sweep,   Builder::binned,
          Builder::lbvh,   Builder::treelet, Builder::spatial};
}

std::filesystem::path test_temp_dir() {
  struct Dir {  // removed when the test program exits
    std::filesystem::path path =
        std::filesystem::temp_directory_path() / ("kestrel_tests_" + std::to_string(::getpid()));
    ~Dir() {
      std::error_code ec;
      std::filesystem::remove_all(path, ec);
    }
  };
  static const Dir dir;
  std::filesystem::create_directories(dir.path);
  return dir.path;
}

std::string write_temp_file(const std::string& name, const std::string& contents) {
  const auto dir = test_temp_dir();
  const std::string path = (dir / name).string();
  std::ofstream(path, std::ios::binary) << contents;
  return path;
}

std::string base64(const std::string& bytes) {
  static const char* t = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
  std::string out;
  size_t i = 0;
  for (; i + 2 < bytes.size(); i += 3) {
    const uint32_t v = uint32_t(uint8_t(bytes[i])) << 16 | uint32_t(uint8_t(bytes[i + 1])) << 8 |
                       uint8_t(bytes[i + 2]);
    out += {t[v >> 18], t[(v >> 12) & 63], t[(v >> 6) & 63], t[v & 63]};
  }
  if (i + 1 == bytes.size()) {
    const uint32_t v = uint32_t(uint8_t(bytes[i])) << 16;
    out += {t[v >> 18], t[(v >> 12) & 63], '=', '='};
  } else if (i + 2 == bytes.size()) {
    const uint32_t v = uint32_t(uint8_t(bytes[i])) << 16 | uint32_t(uint8_t(bytes[i + 1])) << 8;
    out += {t[v >> 18], t[(v >> 12) & 63], t[(v >> 6) & 63], '='};
  }
  return out;
}

std::string write_animated_gltf(const std::string& name) {
  const TriangleMesh box = closed_box({-0.5f, -0.5f, -0.5f}, {0.5f, 0.5f, 0.5f}).meshes[0];
  const TriangleMesh soup = random_soup(60, 0.3f, 5).meshes[0];
  std::string bin;
  std::string views, accessors;
  auto add = [&](const void* data, size_t bytes, size_t count, const char* type, int component,
                 const std::string& extra) {
    const size_t offset = bin.size();
    bin.append(static_cast<const char*>(data), bytes);
    while (bin.size() % 4) bin.push_back('\0');
    const size_t index = std::count(views.begin(), views.end(), '{');
    views += fmt::format("{}{{\"buffer\": 0, \"byteOffset\": {}, \"byteLength\": {}}}",
                         views.empty() ? "" : ", ", offset, bytes);
    accessors += fmt::format(
        "{}{{\"bufferView\": {}, \"componentType\": {}, \"count\": {}, \"type\": \"{}\"{}}}",
        accessors.empty() ? "" : ", ", index, component, count, type, extra);
    return index;
  };
  auto bounds = [](const std::vector<Vec3>& p) {
    Bounds3 b;
    for (const Vec3& v : p) extend(b, v);
    return fmt::format(", \"min\": [{}, {}, {}], \"max\": [{}, {}, {}]", b.lo.x, b.lo.y, b.lo.z,
                       b.hi.x, b.hi.y, b.hi.z);
  };
  const size_t box_pos = add(box.positions.data(), box.positions.size() * 12, box.positions.size(),
                             "VEC3", 5126, bounds(box.positions));
  const size_t box_idx =
      add(box.indices.data(), box.indices.size() * 4, box.indices.size(), "SCALAR", 5125, "");
  const size_t soup_pos = add(soup.positions.data(), soup.positions.size() * 12,
                              soup.positions.size(), "VEC3", 5126, bounds(soup.positions));
  const size_t soup_idx =
      add(soup.indices.data(), soup.indices.size() * 4, soup.indices.size(), "SCALAR", 5125, "");
  const std::vector<Vec3> delta(soup.positions.size(), Vec3{0, 0.3f, 0});
  const size_t soup_target =
      add(delta.data(), delta.size() * 12, delta.size(), "VEC3", 5126, bounds(delta));
  const float times[2] = {0, 2}, moves[6] = {0, 0, 0, 0, 1, 0}, weights[2] = {0, 1};
  const size_t t_acc = add(times, 8, 2, "SCALAR", 5126, ", \"min\": [0], \"max\": [2]");
  const size_t move_acc = add(moves, 24, 2, "VEC3", 5126, "");
  const size_t weight_acc = add(weights, 8, 2, "SCALAR", 5126, "");
  const std::string json = fmt::format(
      R"({{"asset": {{"version": "2.0"}},
  "buffers": [{{"byteLength": {}, "uri": "data:application/octet-stream;base64,{}"}}],
  "bufferViews": [{}], "accessors": [{}],
  "materials": [{{"name": "red", "pbrMetallicRoughness": {{"baseColorFactor": [0.8, 0.1, 0.1, 1]}}}}],
  "meshes": [{{"name": "box", "primitives": [{{"attributes": {{"POSITION": {}}}, "indices": {}, "material": 0}}]}},
             {{"name": "soup", "primitives": [{{"attributes": {{"POSITION": {}}}, "indices": {}, "targets": [{{"POSITION": {}}}]}}],
              "weights": [0]}}],
  "nodes": [{{"mesh": 0, "children": [1]}}, {{"mesh": 0, "translation": [3, 0, 0]}}, {{"mesh": 1, "translation": [0, 0, 2]}}],
  "scenes": [{{"nodes": [0, 2]}}], "scene": 0,
  "animations": [{{"channels": [{{"sampler": 0, "target": {{"node": 0, "path": "translation"}}}},
                               {{"sampler": 1, "target": {{"node": 2, "path": "weights"}}}}],
                  "samplers": [{{"input": {}, "output": {}}}, {{"input": {}, "output": {}}}]}}]}})",
      bin.size(), base64(bin), views, accessors, box_pos, box_idx, soup_pos, soup_idx, soup_target,
      t_acc, move_acc, t_acc, weight_acc);
  return write_temp_file(name, json);
}

std::vector<Isa> supported_isas() {
  std::vector<Isa> out;
  for (Isa isa : {Isa::sse2, Isa::avx2, Isa::avx512})
    if (isa_supported(isa)) out.push_back(isa);
  return out;
}

Accel build_layout(const Scene& scene, Builder builder, Layout layout) {
  BuildConfig c;
  c.builder = builder;
  c.layout = layout;
  return build_accel(scene, c);
}

uint32_t float_bits(float f) {
  uint32_t u;
  std::memcpy(&u, &f, 4);
  return u;
}

ImageMatch match_images(const FloatImage& out, const FloatImage& expected) {
  ImageMatch m;
  EXPECT_EQ(out.width, expected.width);
  EXPECT_EQ(out.height, expected.height);
  if (out.pixels.size() != expected.pixels.size()) {  // no score: fails whatever is asked of it
    m.worst = std::numeric_limits<double>::infinity();
    m.psnr = -std::numeric_limits<double>::infinity();
    return m;
  }
  double se = 0;
  const size_t n = std::min(out.pixels.size(), expected.pixels.size());
  for (size_t i = 0; i < n; ++i) {
    const double e = std::abs(double(out.pixels[i]) - expected.pixels[i]);
    m.worst = std::max(m.worst, e / (std::abs(double(expected.pixels[i])) + 1e-2));
    se += e * e;
  }
  m.psnr = 10 * std::log10(double(std::max<size_t>(n, 1)) / std::max(se, 1e-30));
  return m;
}

ChiSquare chi_square(const std::vector<double>& expected, const std::vector<double>& observed) {
  ChiSquare r;
  for (size_t k = 0; k < expected.size() && k < observed.size(); ++k) {
    if (expected[k] < 5) {
      r.pool_observed += observed[k], r.pool_expected += expected[k];
      continue;
    }
    r.chi2 += (observed[k] - expected[k]) * (observed[k] - expected[k]) / expected[k];
    ++r.cells;
  }
  if (r.pool_expected >= 5) {
    const double d = r.pool_observed - r.pool_expected;
    r.chi2 += d * d / r.pool_expected, ++r.cells;
  }
  const int k = std::max(1, r.cells - 1);
  const double z = (std::cbrt(r.chi2 / k) - (1.0 - 2.0 / (9.0 * k))) / std::sqrt(2.0 / (9.0 * k));
  r.p = 0.5 * std::erfc(z / std::sqrt(2.0));
  return r;
}

}  // namespace kestrel::test
