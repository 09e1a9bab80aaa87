// Built-in scenes, so the CLI and tests work with no file at all.
#include <fmt/format.h>
#include <fmt/ranges.h>

#include "io/loaders.h"
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

}  // namespace

std::vector<std::string> builtin_scene_names() {
  return {"cornell_box"};
}

Scene make_builtin_scene(const std::string& name) {
  if (name == "cornell_box") return cornell_box();
  throw Error(ErrorCode::invalid_argument,
              fmt::format("builtin:{}: no such built-in scene (known: {})", name,
                          fmt::join(builtin_scene_names(), ", ")));
}

}  // namespace kestrel
