// Cut-out opacity against closed forms: a masked quad over a floor lit by a point light. Where
// the mask is clear, camera rays see the floor through it and shadow rays pass it (the floor's
// radiance is rho / pi x I cos / d^2, as without the quad); where it is solid, the camera sees
// the quad and the floor under it is dark. A blended surface is seen by a fraction alpha of
// the rays, the same for any thread count.
#include <gtest/gtest.h>

#include <cmath>

#include "kestrel/kestrel.h"
#include "support/scene_renderer.h"

namespace kestrel {
namespace {

using test::SceneRenderer;

constexpr float kPi = 3.14159265358979f;
const Vec3 kFloor{0.5f, 0.5f, 0.5f}, kQuad{0.9f, 0.1f, 0.1f}, kLight{0, 5, 0};
constexpr float kIntensity = 10;

void add_quad(TriangleMesh& m, Vec3 a, Vec3 b, Vec3 c, Vec3 d, uint32_t material,
              bool uvs = false) {
  const uint32_t base = uint32_t(m.positions.size());
  for (Vec3 p : {a, b, c, d}) m.positions.push_back(p);
  if (uvs) m.uvs.insert(m.uvs.end(), {{0, 0}, {1, 0}, {1, 1}, {0, 1}});
  for (uint32_t i : {0u, 1u, 2u, 0u, 2u, 3u}) m.indices.push_back(base + i);
  m.material_ids.push_back(material), m.material_ids.push_back(material);
}

// A 40 x 40 floor at y = 0 and a 4 x 4 quad at y = 1 whose uvs run along x; its texture's A
// channel is 0 for x < 0 and 255 for x > 0; a point light at (0, 5, 0).
Scene masked_scene(Material::AlphaMode mode) {
  Scene s;
  s.source = "test:cutouts";
  Material quad{.name = "quad", .base_color = kQuad};
  quad.alpha_mode = mode;
  quad.alpha_texture = 0;
  Texture t;
  t.width = t.height = 64;
  for (int y = 0; y < 64; ++y)
    for (int x = 0; x < 64; ++x)
      t.rgba.insert(t.rgba.end(), {200, 200, 200, uint8_t(x < 32 ? 0 : 255)});
  s.textures = {t};
  s.materials = {Material{.name = "floor", .base_color = kFloor}, quad};
  TriangleMesh m;
  add_quad(m, {-20, 0, 20}, {20, 0, 20}, {20, 0, -20}, {-20, 0, -20}, 0, true);
  add_quad(m, {-2, 1, 2}, {2, 1, 2}, {2, 1, -2}, {-2, 1, -2}, 1, true);
  s.meshes.push_back(m);
  Light l{.name = "bulb", .type = Light::Type::point, .position = kLight, .intensity = kIntensity};
  s.lights = {l};
  return s;
}

// The one pixel of a 1 x 1 image looking from (0, 8, 6) at `target`: direct light only.
struct Pixel {
  float color, albedo;
};
Pixel look_at(SceneRenderer& r, Vec3 target) {
  RenderSettings s;
  s.width = s.height = 1, s.spp = 1, s.max_depth = 2, s.jitter = false;
  const Frame f = r.render(Camera{{0, 8, 6}, target, 10}, s);
  return {f[Aov::color].pixels[0], f[Aov::albedo].pixels[0]};
}

// The floor's radiance at p lit by the light, unshadowed.
float lit_floor(Vec3 p) {
  const Vec3 d = kLight - p;
  const float d2 = dot(d, d);
  return kFloor.x / kPi * kIntensity * (d.y / std::sqrt(d2)) / d2;
}

TEST(Cutouts, MaskedSurfacesAreNotThereWhereTheMaskIsClear) {
  for (const auto mode : {Material::AlphaMode::mask, Material::AlphaMode::opaque}) {
    SceneRenderer r(masked_scene(mode), Environment::parse("none"));
    const bool cut = mode == Material::AlphaMode::mask;
    // Seen through the clear half (the camera ray meets the quad at x = -0.875), lit through
    // it (the shadow ray at x = -0.8).
    Pixel p = look_at(r, {-1, 0, 0});
    if (cut) {
      EXPECT_FLOAT_EQ(p.albedo, kFloor.x);
      EXPECT_NEAR(p.color, lit_floor({-1, 0, 0}), 1e-4f * lit_floor({-1, 0, 0}));
    } else {
      EXPECT_FLOAT_EQ(p.albedo, kQuad.x);
    }
    // Through the solid half: the quad.
    p = look_at(r, {1, 0, 0});
    EXPECT_FLOAT_EQ(p.albedo, kQuad.x);
    // Seen past the quad's edge; the shadow ray crosses the clear half (x = -1.92): lit.
    p = look_at(r, {-2.4f, 0, -2.2f});
    EXPECT_FLOAT_EQ(p.albedo, kFloor.x);
    if (cut)
      EXPECT_NEAR(p.color, lit_floor({-2.4f, 0, -2.2f}), 1e-4f * lit_floor({-2.4f, 0, -2.2f}));
    else
      EXPECT_EQ(p.color, 0.0f);
    // The same past the other edge, the shadow ray crossing the solid half: dark.
    p = look_at(r, {2.4f, 0, -2.2f});
    EXPECT_FLOAT_EQ(p.albedo, kFloor.x);
    EXPECT_EQ(p.color, 0.0f);
  }
}

TEST(Cutouts, BlendedSurfacesAreSeenByAlphaOfTheRaysForAnyThreads) {
  Scene s = masked_scene(Material::AlphaMode::blend);
  s.materials[1].alpha_texture = -1;
  s.materials[1].alpha = 0.25f;
  SceneRenderer r(std::move(s), Environment::parse("none"));
  RenderSettings rs;
  rs.width = rs.height = 8, rs.spp = 256, rs.max_depth = 2;
  const Camera cam{{0, 8, 0.01f}, {0, 0, 0}, 10};  // straight down through the quad
  rs.threads = 1;
  const Frame one = r.render(cam, rs);
  rs.threads = 2;
  const Frame two = r.render(cam, rs);
  EXPECT_EQ(one[Aov::color].pixels, two[Aov::color].pixels);
  double albedo = 0;
  for (size_t i = 0; i < one[Aov::albedo].pixels.size(); i += 3)
    albedo += one[Aov::albedo].pixels[i];
  albedo /= double(one[Aov::albedo].pixels.size() / 3);
  // Red albedo: 0.25 x the quad's + 0.75 x the floor's; 16 384 draws (sd 0.0034 x 0.4).
  EXPECT_NEAR(albedo, 0.25 * kQuad.x + 0.75 * kFloor.x, 0.01);
}

}  // namespace
}  // namespace kestrel
