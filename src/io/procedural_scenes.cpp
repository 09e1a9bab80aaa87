// Procedural built-in scenes for benchmarks and tests: shapes of geometry the shared scenes
// lack, each from a fixed seed (the same triangles on every machine and compiler: an own
// integer generator, no std distributions).
//   soup          400 000 triangles of every size and orientation, overlapping, in a cube
//   hairball      5 000 tangled strands of thin three-sided tubes in a ball (720 000)
//   terrain       a 512 x 512 height field of fractal noise (522 242)
//   sphere_field  1 000 tessellated spheres of many sizes on a ground plane (528 002)
#include <cmath>
#include <cstdint>

#include "core/splitmix.h"
#include "io/procedural_scenes.h"

namespace kestrel {

namespace {

// A fixed stream from a seed, with the shapes the generators draw.
struct Rng : SplitMix64 {
  explicit Rng(uint64_t seed) : SplitMix64{seed} {}
  using SplitMix64::uniform;
  float uniform(float lo, float hi) { return lo + (hi - lo) * uniform(); }
  Vec3 on_sphere() {
    const float z = uniform(-1, 1), phi = uniform(0, 6.2831853f);
    const float r = std::sqrt(std::fmax(0.0f, 1 - z * z));
    return {r * std::cos(phi), r * std::sin(phi), z};
  }
};

struct MeshBuilder {
  TriangleMesh mesh;
  uint32_t vertex(Vec3 p) {
    mesh.positions.push_back(p);
    return uint32_t(mesh.positions.size() - 1);
  }
  void triangle(uint32_t a, uint32_t b, uint32_t c, uint32_t material = 0) {
    mesh.indices.insert(mesh.indices.end(), {a, b, c});
    mesh.material_ids.push_back(material);
  }
};

Scene one_mesh(const std::string& name, std::vector<Material> materials, MeshBuilder&& b) {
  Scene scene;
  scene.source = "builtin:" + name;
  scene.materials = std::move(materials);
  b.mesh.name = name;
  scene.meshes.push_back(std::move(b.mesh));
  return scene;
}

Scene soup() {
  Rng rng{101};
  MeshBuilder b;
  constexpr int count = 400000;
  b.mesh.positions.reserve(3 * count);
  for (int i = 0; i < count; ++i) {
    const Vec3 centre{rng.uniform(0, 10), rng.uniform(0, 10), rng.uniform(0, 10)};
    const float size = 0.01f * std::pow(50.0f, rng.uniform());  // 1 cm .. 50 cm, log-uniform
    uint32_t v[3];
    for (uint32_t& k : v) k = b.vertex(centre + rng.on_sphere() * (size * rng.uniform(0.2f, 1)));
    b.triangle(v[0], v[1], v[2]);
  }
  return one_mesh("soup", {{.name = "grey", .base_color = {0.6f, 0.6f, 0.6f}}}, std::move(b));
}

// Strands: smooth random walks inside the unit ball (steered back when they leave it), each
// segment a three-sided tube of radius 4 mm.
Scene hairball() {
  Rng rng{202};
  MeshBuilder b;
  constexpr int strands = 5000, segments = 24;
  constexpr float radius = 0.004f, step = 0.06f;
  for (int s = 0; s < strands; ++s) {
    Vec3 p = rng.on_sphere() * rng.uniform(0.2f, 0.95f);
    Vec3 dir = rng.on_sphere();
    uint32_t ring[3] = {0, 0, 0};
    for (int k = 0; k <= segments; ++k) {
      // A frame around the direction: two unit vectors orthogonal to it.
      const Vec3 helper = std::fabs(dir.x) < 0.9f ? Vec3{1, 0, 0} : Vec3{0, 1, 0};
      const Vec3 u = normalize(cross(dir, helper)), w = cross(dir, u);
      uint32_t next[3];
      for (int c = 0; c < 3; ++c) {
        const float a = 2.0943951f * float(c);
        next[c] = b.vertex(p + (u * std::cos(a) + w * std::sin(a)) * radius);
      }
      if (k > 0)
        for (int c = 0; c < 3; ++c) {
          const int d = (c + 1) % 3;
          b.triangle(ring[c], ring[d], next[d]);
          b.triangle(ring[c], next[d], next[c]);
        }
      for (int c = 0; c < 3; ++c) ring[c] = next[c];
      dir = normalize(dir + rng.on_sphere() * 0.5f - (dot(p, p) > 0.9f ? p : Vec3{}));
      p = p + dir * step;
    }
  }
  return one_mesh("hairball", {{.name = "hair", .base_color = {0.55f, 0.4f, 0.25f}}}, std::move(b));
}

// Value noise on an integer lattice, smoothly interpolated; fractal sums of it.
float lattice(int x, int y, uint64_t seed) {
  Rng r{seed ^ (uint64_t(uint32_t(x)) << 32 | uint32_t(y))};
  return r.uniform();
}
float value_noise(float x, float y, uint64_t seed) {
  const float fx = std::floor(x), fy = std::floor(y);
  const int ix = int(fx), iy = int(fy);
  const float tx = x - fx, ty = y - fy;
  const float sx = tx * tx * (3 - 2 * tx), sy = ty * ty * (3 - 2 * ty);
  const float a = lattice(ix, iy, seed), c = lattice(ix + 1, iy, seed);
  const float d = lattice(ix, iy + 1, seed), e = lattice(ix + 1, iy + 1, seed);
  return (a + (c - a) * sx) + ((d + (e - d) * sx) - (a + (c - a) * sx)) * sy;
}

Scene terrain() {
  constexpr int n = 512;  // vertices per side
  constexpr float extent = 100.0f;
  MeshBuilder b;
  b.mesh.positions.reserve(size_t(n) * n);
  for (int j = 0; j < n; ++j)
    for (int i = 0; i < n; ++i) {
      const float x = extent * float(i) / float(n - 1), z = extent * float(j) / float(n - 1);
      float h = 0, amplitude = 12, frequency = 0.02f;
      for (int octave = 0; octave < 7; ++octave) {
        const float v = value_noise(x * frequency, z * frequency, 303 + octave);
        h += amplitude * (octave < 2 ? v : 1 - std::fabs(2 * v - 1));  // ridges above
        amplitude *= 0.45f;
        frequency *= 2.1f;
      }
      b.vertex({x, h, z});
    }
  for (int j = 0; j + 1 < n; ++j)
    for (int i = 0; i + 1 < n; ++i) {
      const uint32_t v = uint32_t(j * n + i);
      b.triangle(v, v + n, v + 1);
      b.triangle(v + 1, v + n, v + n + 1);
    }
  return one_mesh("terrain", {{.name = "ground", .base_color = {0.45f, 0.42f, 0.35f}}},
                  std::move(b));
}

Scene sphere_field() {
  Rng rng{404};
  MeshBuilder b;
  constexpr float extent = 100.0f;
  const uint32_t g[4] = {b.vertex({0, 0, 0}), b.vertex({0, 0, extent}),
                         b.vertex({extent, 0, extent}), b.vertex({extent, 0, 0})};
  b.triangle(g[0], g[1], g[2]);
  b.triangle(g[0], g[2], g[3]);
  constexpr int spheres = 1000, stacks = 12, slices = 24;
  for (int s = 0; s < spheres; ++s) {
    const float r = 0.2f * std::pow(10.0f, rng.uniform());  // 0.2 .. 2
    const Vec3 c{rng.uniform(0, extent), r, rng.uniform(0, extent)};
    const uint32_t material = 1 + uint32_t(s % 3);
    const uint32_t top = b.vertex(c + Vec3{0, r, 0});
    const uint32_t first = uint32_t(b.mesh.positions.size());
    for (int i = 1; i < stacks; ++i) {
      const float theta = 3.14159265f * float(i) / float(stacks);
      for (int k = 0; k < slices; ++k) {
        const float phi = 6.2831853f * float(k) / float(slices);
        b.vertex(c + Vec3{std::sin(theta) * std::cos(phi), std::cos(theta),
                          std::sin(theta) * std::sin(phi)} *
                         r);
      }
    }
    const uint32_t bottom = b.vertex(c - Vec3{0, r, 0});
    auto at = [&](int ring, int k) { return first + uint32_t(ring * slices + (k % slices)); };
    for (int k = 0; k < slices; ++k) {
      b.triangle(top, at(0, k + 1), at(0, k), material);
      b.triangle(bottom, at(stacks - 2, k), at(stacks - 2, k + 1), material);
      for (int i = 0; i + 1 < stacks - 1; ++i) {
        b.triangle(at(i, k), at(i, k + 1), at(i + 1, k + 1), material);
        b.triangle(at(i, k), at(i + 1, k + 1), at(i + 1, k), material);
      }
    }
  }
  return one_mesh(
      "sphere_field",
      {{.name = "ground", .base_color = {0.5f, 0.5f, 0.5f}},
       {.name = "red", .base_color = {0.7f, 0.2f, 0.15f}},
       {.name = "blue", .base_color = {0.2f, 0.3f, 0.7f}},
       {.name = "gold", .base_color = {0.8f, 0.6f, 0.2f}, .metallic = 1.0f, .roughness = 0.3f}},
      std::move(b));
}

}  // namespace

std::vector<std::string> procedural_scene_names() {
  return {"soup", "hairball", "terrain", "sphere_field"};
}

std::optional<Scene> make_procedural_scene(const std::string& name) {
  if (name == "soup") return soup();
  if (name == "hairball") return hairball();
  if (name == "terrain") return terrain();
  if (name == "sphere_field") return sphere_field();
  return std::nullopt;
}

}  // namespace kestrel
