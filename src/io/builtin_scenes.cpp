// Built-in scenes, so the CLI and tests work with no file at all.
#include <fmt/format.h>
#include <fmt/ranges.h>

#include <cmath>

#include "io/loaders.h"
#include "io/procedural_scenes.h"
#include "kestrel/error.h"

namespace kestrel {

namespace {

// The Cornell box from the measured data published by the Cornell Program of Computer
// Graphics (millimetres; scaled to metres here). Quads are listed counter-clockwise as seen
// from inside the box.
Scene cornell_box() {
  struct Quad {
    float p[4][3];
    int material;
  };
  enum { white, red, green, light };
  const Quad quads[] = {
      {{{552.8f, 0, 0}, {0, 0, 0}, {0, 0, 559.2f}, {549.6f, 0, 559.2f}}, white},  // floor
      {{{556, 548.8f, 0}, {556, 548.8f, 559.2f}, {0, 548.8f, 559.2f}, {0, 548.8f, 0}},
       white},  // ceiling
      {{{549.6f, 0, 559.2f}, {0, 0, 559.2f}, {0, 548.8f, 559.2f}, {556, 548.8f, 559.2f}},
       white},                                                                    // back
      {{{0, 0, 559.2f}, {0, 0, 0}, {0, 548.8f, 0}, {0, 548.8f, 559.2f}}, green},  // right
      {{{552.8f, 0, 0}, {549.6f, 0, 559.2f}, {556, 548.8f, 559.2f}, {556, 548.8f, 0}},
       red},  // left
      {{{343, 548.7f, 227}, {343, 548.7f, 332}, {213, 548.7f, 332}, {213, 548.7f, 227}},
       light},  // lamp
      // short block
      {{{130, 165, 65}, {82, 165, 225}, {240, 165, 272}, {290, 165, 114}}, white},
      {{{290, 0, 114}, {290, 165, 114}, {240, 165, 272}, {240, 0, 272}}, white},
      {{{130, 0, 65}, {130, 165, 65}, {290, 165, 114}, {290, 0, 114}}, white},
      {{{82, 0, 225}, {82, 165, 225}, {130, 165, 65}, {130, 0, 65}}, white},
      {{{240, 0, 272}, {240, 165, 272}, {82, 165, 225}, {82, 0, 225}}, white},
      // tall block
      {{{423, 330, 247}, {265, 330, 296}, {314, 330, 456}, {472, 330, 406}}, white},
      {{{423, 0, 247}, {423, 330, 247}, {472, 330, 406}, {472, 0, 406}}, white},
      {{{472, 0, 406}, {472, 330, 406}, {314, 330, 456}, {314, 0, 456}}, white},
      {{{314, 0, 456}, {314, 330, 456}, {265, 330, 296}, {265, 0, 296}}, white},
      {{{265, 0, 296}, {265, 330, 296}, {423, 330, 247}, {423, 0, 247}}, white},
  };
  Scene scene;
  scene.source = "builtin:cornell_box";
  scene.materials = {
      {.name = "white", .base_color = {0.73f, 0.73f, 0.73f}},
      {.name = "red", .base_color = {0.63f, 0.065f, 0.05f}},
      {.name = "green", .base_color = {0.14f, 0.45f, 0.091f}},
      {.name = "light", .base_color = {0.78f, 0.78f, 0.78f}, .emission = {17.0f, 12.0f, 4.0f}}};
  TriangleMesh mesh;
  mesh.name = "cornell_box";
  for (const Quad& q : quads) {
    const uint32_t base = uint32_t(mesh.positions.size());
    for (const auto& p : q.p)
      mesh.positions.push_back({p[0] * 0.001f, p[1] * 0.001f, p[2] * 0.001f});
    for (uint32_t k : {0u, 1u, 2u, 0u, 2u, 3u}) mesh.indices.push_back(base + k);
    mesh.material_ids.push_back(uint32_t(q.material));
    mesh.material_ids.push_back(uint32_t(q.material));
  }
  scene.meshes.push_back(std::move(mesh));
  return scene;
}

// A night hall of lamps, for many-light sampling: a 64 x 64 m floor under a ceiling at 6 m,
// walls, 400 pillars, and 32 x 32 = 1024 small emissive squares (20 cm) hanging at 2.5 m
// whose power spans two decades and whose colours vary (a fixed pseudo-random pattern).
// No sky: every photon comes from a lamp. Views: "inside" is its data/views entry.
Scene lamp_hall() {
  Scene scene;
  scene.source = "builtin:lamp_hall";
  scene.materials = {{.name = "floor", .base_color = {0.5f, 0.5f, 0.5f}},
                     {.name = "wall", .base_color = {0.6f, 0.55f, 0.5f}}};
  TriangleMesh mesh;
  mesh.name = "lamp_hall";
  auto quad = [&](Vec3 a, Vec3 b, Vec3 c, Vec3 d, uint32_t material) {
    const uint32_t base = uint32_t(mesh.positions.size());
    mesh.positions.insert(mesh.positions.end(), {a, b, c, d});
    for (uint32_t k : {0u, 1u, 2u, 0u, 2u, 3u}) mesh.indices.push_back(base + k);
    mesh.material_ids.insert(mesh.material_ids.end(), {material, material});
  };
  auto box = [&](Vec3 lo, Vec3 hi, uint32_t m) {
    quad({lo.x, lo.y, lo.z}, {hi.x, lo.y, lo.z}, {hi.x, hi.y, lo.z}, {lo.x, hi.y, lo.z}, m);
    quad({lo.x, lo.y, hi.z}, {lo.x, hi.y, hi.z}, {hi.x, hi.y, hi.z}, {hi.x, lo.y, hi.z}, m);
    quad({lo.x, lo.y, lo.z}, {lo.x, hi.y, lo.z}, {lo.x, hi.y, hi.z}, {lo.x, lo.y, hi.z}, m);
    quad({hi.x, lo.y, lo.z}, {hi.x, lo.y, hi.z}, {hi.x, hi.y, hi.z}, {hi.x, hi.y, lo.z}, m);
    quad({lo.x, hi.y, lo.z}, {hi.x, hi.y, lo.z}, {hi.x, hi.y, hi.z}, {lo.x, hi.y, hi.z}, m);
  };
  const float h = 32;
  quad({-h, 0, -h}, {-h, 0, h}, {h, 0, h}, {h, 0, -h}, 0);    // floor
  quad({-h, 6, -h}, {h, 6, -h}, {h, 6, h}, {-h, 6, h}, 1);    // ceiling
  quad({-h, 0, -h}, {h, 0, -h}, {h, 6, -h}, {-h, 6, -h}, 1);  // walls
  quad({-h, 0, h}, {-h, 6, h}, {h, 6, h}, {h, 0, h}, 1);
  quad({-h, 0, -h}, {-h, 6, -h}, {-h, 6, h}, {-h, 0, h}, 1);
  quad({h, 0, -h}, {h, 0, h}, {h, 6, h}, {h, 6, -h}, 1);
  for (int i = 0; i < 20; ++i)
    for (int j = 0; j < 20; ++j) {
      const float x = -30.4f + 3.2f * float(i), z = -30.4f + 3.2f * float(j);
      box({x - 0.2f, 0, z - 0.2f}, {x + 0.2f, 6, z + 0.2f}, 1);  // pillars
    }
  uint32_t state = 12345u;
  auto next = [&] {  // a fixed LCG: the same hall on every machine
    state = state * 1664525u + 1013904223u;
    return float(state >> 8) * (1.0f / 16777216.0f);
  };
  for (int i = 0; i < 32; ++i)
    for (int j = 0; j < 32; ++j) {
      const float x = -31 + 2 * float(i) + 0.5f * next(), z = -31 + 2 * float(j) + 0.5f * next();
      const float power = 2 * std::pow(10.0f, 2 * next());  // 2 .. 200
      const Vec3 tint{0.6f + 0.4f * next(), 0.5f + 0.4f * next(), 0.3f + 0.5f * next()};
      const uint32_t m = uint32_t(scene.materials.size());
      scene.materials.push_back({.name = fmt::format("lamp{}", i * 32 + j),
                                 .base_color = {0.8f, 0.8f, 0.8f},
                                 .emission = tint * power});
      quad({x - 0.1f, 2.5f, z - 0.1f}, {x + 0.1f, 2.5f, z - 0.1f}, {x + 0.1f, 2.5f, z + 0.1f},
           {x - 0.1f, 2.5f, z + 0.1f}, m);
    }
  scene.meshes.push_back(std::move(mesh));
  return scene;
}

}  // namespace

std::vector<std::string> builtin_scene_names() {
  std::vector<std::string> names = {"cornell_box", "lamp_hall"};
  for (std::string& n : procedural_scene_names()) names.push_back(std::move(n));
  return names;
}

Scene make_builtin_scene(const std::string& name) {
  if (name == "cornell_box") return cornell_box();
  if (name == "lamp_hall") return lamp_hall();
  if (std::optional<Scene> scene = make_procedural_scene(name)) return std::move(*scene);
  throw Error(ErrorCode::invalid_argument,
              fmt::format("builtin:{}: no such built-in scene (known: {})", name,
                          fmt::join(builtin_scene_names(), ", ")));
}

}  // namespace kestrel
