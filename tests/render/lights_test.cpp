// Punctual lights, the sun and the physical sky against closed forms: a Lambertian plane seen
// straight on lit by one light, where the reflected radiance is rho / pi x the irradiance the
// light gives it; the glTF KHR_lights_punctual loader; every bad light a clear error.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>

#include "core/vec.h"
#include "kestrel/kestrel.h"
#include "render/light_tree.h"
#include "render/testing.h"
#include "support/oracles.h"

namespace kestrel {
namespace {

constexpr float kPi = 3.14159265358979f;
constexpr float kAlbedo = 0.5f;

// A 40 x 40 Lambertian plane at z = -5 facing +z (the camera at the origin looks at it).
Scene plane() {
  return test::lit_plane(kAlbedo, "test:lit_plane");
}

// The radiance of the pixel looking straight at (x, y, -5) (one pixel, no jitter), direct
// light only (NEE at the first hit; the bounce escapes into a black environment).
float radiance_at(Scene scene, std::optional<Environment> env, int spp = 1, float x = 0,
                  float y = 0) {
  const Asset asset = Asset::from_scene(std::move(scene));
  Renderer r(asset.scene(), env ? env : Environment::parse("none"));
  RenderSettings s;
  s.width = s.height = 1, s.spp = spp, s.max_depth = 2, s.jitter = false;
  const Frame f = r.render(Camera{{x, y, 0}, {x, y, -5}, 10}, s);
  return f[Aov::color].pixels[1];  // green
}

TEST(Lights, PointLightIsIntensityOverDistanceSquared) {
  Scene s = plane();
  s.lights.push_back(
      Light{.name = "bulb", .type = Light::Type::point, .position = {0, 0, -3}, .intensity = 8});
  // E = I / d^2 = 8 / 4 at normal incidence.
  EXPECT_NEAR(radiance_at(s, std::nullopt), kAlbedo / kPi * 2.0f, 1e-4f);
  // Off to the side: E = I cos / d^2 with cos = 2 / d, d^2 = 4 + 2.25.
  s.lights[0].position = {1.5f, 0, -3};
  EXPECT_NEAR(radiance_at(s, std::nullopt), kAlbedo / kPi * 8 * (2 / std::sqrt(6.25f)) / 6.25f,
              1e-4f);
  // glTF's range window (1 - (d / range)^4)^2 at d = 2, range 3.
  s.lights[0].position = {0, 0, -3}, s.lights[0].range = 3;
  const float win = 1 - std::pow(2.0f / 3.0f, 4.0f);
  EXPECT_NEAR(radiance_at(s, std::nullopt), kAlbedo / kPi * 2.0f * win * win, 1e-4f);
}

TEST(Lights, SpotLightFollowsItsCone) {
  Scene s = plane();
  Light spot{.name = "spot",
             .type = Light::Type::spot,
             .position = {0, 0, -3},
             .direction = {0, 0, -1},
             .intensity = 8,
             .inner_cone = 0.2f,
             .outer_cone = 0.4f};
  s.lights.push_back(spot);
  EXPECT_NEAR(radiance_at(s, std::nullopt), kAlbedo / kPi * 2.0f, 1e-4f);  // on the axis: full
  // 45 degrees off the axis (outside the outer cone): dark. Between the cones: glTF's
  // smooth edge, ((cos a - cos outer) / (cos inner - cos outer))^2.
  EXPECT_EQ(radiance_at(s, std::nullopt, 1, 2, 0), 0.0f);
  const float a = std::atan(0.6f / 2.0f), d2 = 4 + 0.36f;
  const float t = (std::cos(a) - std::cos(0.4f)) / (std::cos(0.2f) - std::cos(0.4f));
  EXPECT_NEAR(radiance_at(s, std::nullopt, 1, 0.6f, 0),
              kAlbedo / kPi * 8 * (2 / std::sqrt(d2)) / d2 * t * t, 1e-4f);
}

TEST(Lights, DirectionalLightAndSunGiveTheirIrradiance) {
  Scene s = plane();
  s.lights.push_back(
      Light{.name = {}, .type = Light::Type::directional, .direction = {0, 0, -1}, .intensity = 3});
  EXPECT_NEAR(radiance_at(s, std::nullopt), kAlbedo / kPi * 3, 1e-4f);
  // A sun straight above the plane (towards +z), no sky: its irradiance times the mean cosine
  // over its disk (1 - (1 - cos r) / 2, ~1), from NEE and BSDF samples combined by MIS.
  Environment env = Environment::parse("none");
  env.sun = Sun{.direction = {0, 0, 1}, .irradiance = {4, 4, 4}, .angular_radius_degrees = 2};
  const float r = 2 * kPi / 180, mean_cos = 1 - (1 - std::cos(r)) / 2;
  EXPECT_NEAR(radiance_at(plane(), env, 64), kAlbedo / kPi * 4 * mean_cos, 2e-3f);
}

// A normal map tilts the shading normal in the tangent frame of the texture coordinates: a
// constant map tilting by angle a towards +u turns a directional light from angle b into
// rho / pi x E x cos(a - b) (against cos b without it); with the uvs mirrored along u the
// tilt follows the mapping; the SIMD surface rows and the one-by-one path agree; a map
// scale of 0 leaves the normal alone.
// A normal map tilts the shading normal in the tangent frame of the texture coordinates
// (+X along u, +Y against v): a constant map's normal n (decoded from its 8-bit codes) turns
// a directional light from L into rho / pi x E x (n . L); with the uvs mirrored along u, X
// follows u (now along -x) and Y stays against v; the SIMD surface rows and the one-by-one
// path agree; a map scale of 0 leaves the normal alone.
TEST(Lights, NormalMapsTiltTheShadingNormal) {
  auto code = [](float c) { return uint8_t(std::lround((0.5f + 0.5f * c) * 255)); };
  const uint8_t cx = code(std::sin(0.5f)), cy = code(std::sin(0.3f)),
                cz = code(std::cos(0.5f) * std::cos(0.3f));
  const Vec3 n = normalize(Vec3{cx / 255.0f * 2 - 1, cy / 255.0f * 2 - 1, cz / 255.0f * 2 - 1});
  const Vec3 to_light = normalize(Vec3{0.3f, 0.4f, 1.0f});
  auto mapped = [&](bool mirrored, float scale) {
    Scene s = plane();
    s.materials[0].normal_texture = 0;
    s.materials[0].normal_scale = scale;
    Texture t;
    t.width = t.height = 4;
    for (int i = 0; i < 16; ++i) t.rgba.insert(t.rgba.end(), {cx, cy, cz, 255});
    s.textures = {t};
    // Vertices (-20, -20), (20, -20), (20, 20), (-20, 20): u along +x, v against +y.
    s.meshes[0].uvs = {{0, 1}, {1, 1}, {1, 0}, {0, 0}};
    if (mirrored) s.meshes[0].uvs = {{1, 1}, {0, 1}, {0, 0}, {1, 0}};
    s.lights.push_back(Light{
        .name = {}, .type = Light::Type::directional, .direction = -to_light, .intensity = 3});
    return s;
  };
  const float e = kAlbedo / kPi * 3;
  EXPECT_NEAR(radiance_at(mapped(false, 1), std::nullopt), e * dot(n, to_light), 1e-4f);
  EXPECT_NEAR(radiance_at(mapped(true, 1), std::nullopt), e * dot(Vec3{-n.x, n.y, n.z}, to_light),
              1e-4f);
  EXPECT_NEAR(radiance_at(mapped(false, 0), std::nullopt), e * to_light.z, 1e-4f);
  // Many pixels, the SIMD rows and the scalar path: the same image.
  const Asset asset = Asset::from_scene(mapped(false, 1));
  Renderer r(asset.scene(), Environment::parse("none"));
  RenderSettings rs;
  rs.width = rs.height = 16, rs.spp = 2;
  const Camera cam{{0, 0, 0}, {0, 0, -5}, 60};
  const Frame rows = r.render(cam, rs);
  RendererTesting::set_surface_rows(r, false);
  const Frame scalar = r.render(cam, rs);
  EXPECT_EQ(rows[Aov::color].pixels, scalar[Aov::color].pixels);
  EXPECT_EQ(rows[Aov::normal].pixels, scalar[Aov::normal].pixels);
}

TEST(Lights, SunAndEnvironmentSharedByIrradianceStayUnbiased) {
  // NEE splits its choice between the sun and the environment by their irradiance (each
  // at least 1/8): with the sun far brighter, far dimmer and about equal, the plane's
  // radiance is still rho / pi x (the sun's irradiance x its mean cosine + pi L).
  const float r = 2 * kPi / 180, mean_cos = 1 - (1 - std::cos(r)) / 2;
  for (float sun : {40.0f, 0.05f, 1.0f}) {
    Environment env = Environment::parse("constant:0.3,0.3,0.3");
    env.sun =
        Sun{.direction = {0, 0, 1}, .irradiance = {sun, sun, sun}, .angular_radius_degrees = 2};
    const double expected = kAlbedo / kPi * (sun * mean_cos + kPi * 0.3);
    const double got = radiance_at(plane(), env, 16384);
    EXPECT_NEAR(got, expected, 0.01 * expected) << "sun " << sun;
  }
}

// Where the sun outshines the environment, NEE at a Lambertian surface picks among the sun and
// the local lights alone (the cosine-sampled environment is left to the BSDF sample, whose
// density it shares): the sun's, the sky's and an area light's shares are still exact. The
// plane's point under the camera, a 2 x 2 emitter off to the side (it hides a part of the sky):
// rho / pi x (E_sun mean_cos + L_sky (pi - F) + L_e F), F the emitter's cosine-weighted solid
// angle by Lambert's polygon formula. The sun about as bright as the sky, so that NEE's picks
// change most (checked to fail when a BSDF-sampled hit weighs the lamp or the sky as NEE picks
// them elsewhere).
TEST(Lights, EnvironmentLeftToTheBsdfStaysUnbiased) {
  const float r = 2 * kPi / 180, mean_cos = 1 - (1 - std::cos(r)) / 2;
  const Vec3 quad[4] = {{0.5f, -1, -3.5f}, {2.5f, -1, -3.5f}, {2.5f, 1, -3.5f}, {0.5f, 1, -3.5f}};
  double f = 0;  // sum over edges of angle x (n . unit normal of the edge's plane), n = +z
  for (int i = 0; i < 4; ++i) {
    const Vec3 a = normalize(quad[i] - Vec3{0, 0, -5}),
               b = normalize(quad[(i + 1) % 4] - Vec3{0, 0, -5});
    const Vec3 c = cross(a, b);
    f += std::acos(std::clamp(double(dot(a, b)), -1.0, 1.0)) * c.z / length(c);
  }
  const double form = std::fabs(f) / 2;
  for (const bool with_lamp : {false, true}) {
    Scene s = plane();
    if (with_lamp) {
      s.materials.push_back(
          Material{.name = "lamp", .base_color = {0, 0, 0}, .emission = {10, 10, 10}});
      TriangleMesh m;
      m.positions.assign(quad, quad + 4);
      m.indices = {0, 1, 2, 0, 2, 3};
      m.material_ids = {1, 1};
      s.meshes.push_back(m);
    }
    Environment env = Environment::parse("constant:0.3,0.3,0.3");
    env.sun = Sun{.direction = {0, 0, 1}, .irradiance = {1, 1, 1}, .angular_radius_degrees = 2};
    const double sky = with_lamp ? 0.3 * (kPi - form) + 10 * form : 0.3 * kPi;
    const double expected = kAlbedo / kPi * (1 * mean_cos + sky);
    const double got = radiance_at(std::move(s), env, 16384);
    EXPECT_NEAR(got, expected, 0.01 * expected) << (with_lamp ? "with" : "without") << " lamp";
  }
}

// A glTF model's emissive texture (a label, a screen) is its own glow, not the scene's
// lighting: a scene whose only emission comes from textures keeps the default sky, one with
// an untextured emitter does not. Such emitters are sampled by the texture's mean over each
// triangle: a 2 x 2 quad, one triangle textured white and the other black, lights the plane
// as the white triangle alone does (rho / pi x L x its form factor, Lambert's polygon
// formula), and next-event estimation never spends a sample on the black one (the estimate's
// variance stays far below a half-wasted one's, var / mean^2 >= 1).
TEST(Lights, TexturedEmissionIsAGlowSampledByItsTexture) {
  const Vec3 p0{0.5f, -1, -3.5f}, p1{2.5f, -1, -3.5f}, p2{2.5f, 1, -3.5f}, p3{0.5f, 1, -3.5f};
  auto lamp_scene = [&](bool textured) {
    Scene s = plane();
    Material lamp{.name = "lamp", .base_color = {0, 0, 0}, .emission = {10, 10, 10}};
    if (textured) {
      lamp.emission_texture = 0;
      Texture t;
      t.width = t.height = 64;
      for (int y = 0; y < 64; ++y)
        for (int x = 0; x < 64; ++x)
          for (int c = 0; c < 4; ++c) t.rgba.push_back(x < 32 || c == 3 ? 255 : 0);
      s.textures = {t};
    }
    s.materials.push_back(lamp);
    TriangleMesh m;
    m.positions = {p0, p1, p2, p0, p2, p3};
    m.uvs = {{0.1f, 0.1f}, {0.4f, 0.1f}, {0.4f, 0.9f}, {0.6f, 0.1f}, {0.9f, 0.9f}, {0.6f, 0.9f}};
    m.indices = {0, 1, 2, 3, 4, 5};
    m.material_ids = {1, 1};
    s.meshes.push_back(m);
    return s;
  };
  RenderSettings one;
  one.width = one.height = 1, one.spp = 4, one.jitter = false;
  const Camera away{{0, 0, 0}, {0, 0, 5}, 10};  // nothing but the environment that way
  for (const bool textured : {true, false}) {
    const Asset asset = Asset::from_scene(lamp_scene(textured));
    Renderer r(asset.scene());
    const float sky = r.render(away, one)[Aov::color].pixels[1];
    if (textured)
      EXPECT_GT(sky, 0.05f) << "the default sky is on";
    else
      EXPECT_EQ(sky, 0.0f) << "an untextured emitter lights the scene: no default sky";
  }
  // The form factor of a triangle seen from (0, 0, -5), normal +z.
  auto form_factor = [](const Vec3(&tri)[3]) {
    double f = 0;
    for (int i = 0; i < 3; ++i) {
      const Vec3 a = normalize(tri[i] - Vec3{0, 0, -5}),
                 b = normalize(tri[(i + 1) % 3] - Vec3{0, 0, -5});
      const Vec3 c = cross(a, b);
      f += std::acos(std::clamp(double(dot(a, b)), -1.0, 1.0)) * c.z / length(c);
    }
    return std::fabs(f) / 2;
  };
  Asset asset = Asset::from_scene(lamp_scene(true));
  Renderer r(asset.scene(), Environment::parse("none"));
  RenderSettings s = one;
  s.spp = 16384, s.max_depth = 2;
  // Then the texture's halves swapped after a commit: the other triangle lights the plane,
  // and the light choice follows (the means are recomputed, not kept from the first sync).
  for (const bool swapped : {false, true}) {
    if (swapped) {
      std::vector<Texture> textures = asset.scene().textures();
      for (uint8_t& v : textures[0].rgba) v = uint8_t(255 - v);
      for (size_t i = 3; i < textures[0].rgba.size(); i += 4) textures[0].rgba[i] = 255;
      asset.scene().set_materials(asset.scene().materials(), std::move(textures));
      asset.scene().commit();
    }
    const Vec3 white[2][3] = {{p0, p1, p2}, {p0, p2, p3}};
    const double expected = kAlbedo / kPi * 10 * form_factor(white[swapped]);
    const Frame frame = r.render(Camera{{0, 0, 0}, {0, 0, -5}, 10}, s);
    const double got = frame[Aov::color].pixels[1];
    EXPECT_NEAR(got, expected, 0.01 * expected) << (swapped ? "swapped" : "first");
    const double relative_variance = frame[Aov::variance].pixels[0] * s.spp / (got * got);
    EXPECT_LT(relative_variance, 0.5) << (swapped ? "swapped" : "first");
  }
}

TEST(Lights, PhysicalSkyIsNormalisedAndBrightestTowardsTheSun) {
  const Sun sun = Sun::parse("90,45");  // east (+X), 45 degrees up
  EXPECT_NEAR(sun.direction.x, std::sqrt(0.5f), 1e-6f);
  EXPECT_NEAR(sun.direction.y, std::sqrt(0.5f), 1e-6f);
  EXPECT_NEAR(sun.direction.z, 0.0f, 1e-6f);
  const Environment sky = Environment::physical_sky(sun);
  ASSERT_EQ(sky.image.width, 512);
  ASSERT_TRUE(sky.sun.has_value());
  auto lum = [&](int x, int y) {
    const float* p = sky.image.at(x, y);
    return 0.2126f * p[0] + 0.7152f * p[1] + 0.0722f * p[2];
  };
  EXPECT_NEAR(lum(256, 0), 1.0f, 0.05f);  // the zenith of a 45-degree sun, turbidity 3
  // u = 0.5 + atan2(x, -z) / 2 pi: east (+X) at u = 0.75, west at 0.25; 45 degrees up at v = 0.25.
  EXPECT_GT(lum(384 - 20, 64), 2 * lum(128, 64));
  EXPECT_NEAR(lum(10, 250), 0.1f * lum(10, 127), 0.05f * lum(10, 127));  // the ground
  // A low sun's sky is dimmer.
  EXPECT_LT(Environment::physical_sky(Sun::parse("90,5")).image.at(256, 0)[1],
            0.5f * sky.image.at(256, 0)[1]);
}

TEST(Lights, PhysicalSkyIrradianceIsTheSameSampledEitherWay) {
  // The plane (facing +Z) under the physical sky without its sun: the reflected radiance is
  // rho / pi x the integral of L cos over the hemisphere, summed here texel by texel of the
  // sky image (the oracle). The sky's own cosine-weighted light samples and luminance-
  // sampled ones (the same image, cosine_sampled off) must both converge to it.
  Sun sun = Sun::parse("90,35");
  Environment sky = Environment::physical_sky(sun);
  sky.sun.reset();
  ASSERT_TRUE(sky.cosine_sampled);
  const int w = sky.image.width, h = sky.image.height;
  double e = 0;
  for (int y = 0; y < h; ++y) {
    const double theta = kPi * (y + 0.5) / h;
    for (int x = 0; x < w; ++x) {
      const double phi = (double(x) + 0.5) / w * 2 * kPi - kPi;
      const double dz = -std::sin(theta) * std::cos(phi);  // d = (sin sin, cos, -sin cos)
      if (dz > 0) e += sky.image.at(x, y)[1] * dz * std::sin(theta) * (2 * kPi / w) * (kPi / h);
    }
  }
  const double expected = kAlbedo / kPi * e;
  const float cosine = radiance_at(plane(), sky, 8192);
  sky.cosine_sampled = false;
  const float by_luminance = radiance_at(plane(), sky, 8192);
  EXPECT_NEAR(cosine, expected, 0.02 * expected);
  EXPECT_NEAR(by_luminance, expected, 0.02 * expected);
}

// What a camera ray that escapes sees of the physical sky (its sun removed): the image's value
// in that direction, within the smoothness of the sky, and no blend of sky and ground at the
// horizon: just above it, the sky's lowest row; just below, the ground's 0.1 x.
TEST(Lights, SkySeenDirectlyIsTheImageAndTheHorizonStaysSharp) {
  Environment sky = Environment::physical_sky(Sun::parse("90,35"));
  sky.sun.reset();
  const Asset asset = Asset::from_scene(plane());  // behind the camera: every ray escapes
  Renderer r(asset.scene(), sky);
  RenderSettings s;
  s.width = s.height = 1, s.spp = 1, s.max_depth = 1, s.jitter = false;
  const FloatImage& img = sky.image;
  // The direction at azimuth a (degrees from -Z towards +X) and elevation e.
  auto dir = [](float a, float e) {
    const float ar = a * kPi / 180, er = e * kPi / 180;
    return Vec3{std::cos(er) * std::sin(ar), std::sin(er), -std::cos(er) * std::cos(ar)};
  };
  auto seen = [&](Vec3 d) {
    return r.render(Camera{{0, 0, 0}, d, 10}, s)[Aov::color].pixels[1];  // green
  };
  auto texel = [&](Vec3 d) {  // the image's nearest texel (Environment's mapping)
    const float u = 0.5f + std::atan2(d.x, -d.z) / (2 * kPi), v = std::acos(d.y) / kPi;
    return img.at(std::min(int(u * float(img.width)), img.width - 1),
                  std::min(int(v * float(img.height)), img.height - 1))[1];
  };
  int checked = 0;
  for (float a = 100; a <= 260; a += 20)
    for (float e = 3; e <= 85; e += 7) {
      const Vec3 d = dir(a, e);
      EXPECT_NEAR(seen(d), texel(d), 0.03f * texel(d)) << "azimuth " << a << " elevation " << e;
      ++checked;
    }
  EXPECT_GT(checked, 50);
  for (float a : {120.0f, 180.0f, 240.0f}) {
    const float above = seen(dir(a, 0.3f)), below = seen(dir(a, -0.3f));
    const float lowest = texel(dir(a, 0.3f));
    EXPECT_NEAR(above, lowest, 0.03f * lowest) << "azimuth " << a;
    EXPECT_NEAR(below, 0.1f * lowest, 0.01f * lowest) << "azimuth " << a;
  }
}

TEST(Lights, LightingFlags) {
  EXPECT_FALSE(make_lighting("", "", false).has_value());
  EXPECT_FALSE(make_lighting("none", "", false)->sun.has_value());
  const auto sun_sky = make_lighting("", "0,30,5", false);
  ASSERT_TRUE(sun_sky && sun_sky->sun);
  EXPECT_FALSE(sun_sky->image.pixels.empty());  // the physical sky comes with a sun
  EXPECT_FLOAT_EQ(sun_sky->sun->irradiance.x, 5);
  EXPECT_TRUE(make_lighting("", "", true)->sun.has_value());  // --sky: the default sun
  EXPECT_TRUE(make_lighting("none", "0,30", false)->image.pixels.empty());
  for (const char* bad : {"1", "1,2,3,4", "x,10", "0,100", "0,10,-1", "0,nan"}) {
    try {
      Sun::parse(bad);
      ADD_FAILURE() << bad;
    } catch (const Error& e) {
      EXPECT_NE(std::string(e.what()).find(bad), std::string::npos) << e.what();
    }
  }
  EXPECT_THROW(make_lighting("sky", "", true), Error);
}

TEST(Lights, BadLightsAreErrorsNamingSceneAndLight) {
  auto expect = [](Light l, const std::string& needle) {
    Scene s = plane();
    l.name = "lamp7";
    s.lights.push_back(l);
    const Asset asset = Asset::from_scene(std::move(s));
    try {
      Renderer r(asset.scene());
      ADD_FAILURE() << "no error for " << needle;
    } catch (const Error& e) {
      const std::string m = e.what();
      EXPECT_NE(m.find("test:lit_plane"), std::string::npos) << m;
      EXPECT_NE(m.find("lamp7"), std::string::npos) << m;
      EXPECT_NE(m.find(needle), std::string::npos) << m;
    }
  };
  expect(Light{.name = {}, .intensity = -1}, "negative");
  expect(Light{.name = {}, .position = {NAN, 0, 0}}, "NaN");
  expect(Light{.name = {}, .type = Light::Type::spot, .direction = {0, 0, 0}}, "direction");
  expect(Light{.name = {}, .type = Light::Type::directional, .direction = {NAN, 0, 1}},
         "direction");
  expect(Light{.name = {}, .type = Light::Type::spot, .inner_cone = 0.5f, .outer_cone = 0.4f},
         "cone");
}

std::string gltf_with_light(const std::string& name, const std::string& light_json) {
  const TriangleMesh quad = plane().meshes[0];
  // Positions (4 x vec3) then indices (6 x uint32), as a base64 data URI.
  std::string bin(reinterpret_cast<const char*>(quad.positions.data()), 48);
  bin.append(reinterpret_cast<const char*>(quad.indices.data()), 24);
  const std::string b64 = test::base64(bin);
  return test::write_temp_file(
      name, R"({"asset": {"version": "2.0"}, "extensionsUsed": ["KHR_lights_punctual"],
    "buffers": [{"byteLength": 72, "uri": "data:application/octet-stream;base64,)" +
                b64 + R"("}],
    "bufferViews": [{"buffer": 0, "byteOffset": 0, "byteLength": 48}, {"buffer": 0, "byteOffset": 48, "byteLength": 24}],
    "accessors": [{"bufferView": 0, "componentType": 5126, "count": 4, "type": "VEC3", "min": [-20, -20, -5], "max": [20, 20, -5]},
                  {"bufferView": 1, "componentType": 5125, "count": 6, "type": "SCALAR"}],
    "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1}]}],
    "extensions": {"KHR_lights_punctual": {"lights": [)" +
                light_json + R"(]}},
    "nodes": [{"mesh": 0}, {"translation": [0, 0, -3], "extensions": {"KHR_lights_punctual": {"light": 0}}}],
    "scenes": [{"nodes": [0, 1]}], "scene": 0})");
}

TEST(Lights, GltfPunctualLightsLoadPlacedByTheirNodes) {
  const std::string path = gltf_with_light(
      "lit.gltf", R"({"name": "bulb", "type": "point", "intensity": 8, "color": [1, 0.5, 0.25]})");
  for (const bool instanced : {true, false}) {
    SCOPED_TRACE(instanced ? "Asset::load" : "load_scene");
    const std::vector<Light> lights =
        instanced ? Asset::load(path).scene().lights() : load_scene(path).lights;
    ASSERT_EQ(lights.size(), 1u);
    EXPECT_EQ(lights[0].name, "bulb");
    EXPECT_EQ(lights[0].type, Light::Type::point);
    EXPECT_NEAR(lights[0].position.z, -3.0f, 1e-6f);
    EXPECT_FLOAT_EQ(lights[0].color.y, 0.5f);
  }
  // Rendered from the file: the point light's closed form (glTF default material: white-ish
  // base colour 1 in kestrel's default material 0.8).
  const Asset asset = Asset::load(path);
  Renderer r(asset.scene(), Environment::parse("none"));
  RenderSettings s;
  s.width = s.height = 1, s.max_depth = 2, s.jitter = false;
  const Frame f = r.render(Camera{{0, 0, 0}, {0, 0, -5}, 10}, s);
  EXPECT_NEAR(f[Aov::color].pixels[1], 0.8f / kPi * 2.0f * 0.5f, 1e-4f);
  for (
      const auto& [json, needle] : std::vector<std::pair<std::string, std::string>>{
          {R"({"name": "odd", "type": "area", "intensity": 1})", "unknown type 'area'"},
          {R"({"name": "neg", "type": "point", "intensity": -2})", "negative"},
          {R"({"name": "cone", "type": "spot", "spot": {"innerConeAngle": 1.0, "outerConeAngle": 0.5}})",
           "cone"}}) {
    const std::string bad = gltf_with_light("bad_light.gltf", json);
    try {
      Asset::load(bad);
      ADD_FAILURE() << needle;
    } catch (const Error& e) {
      EXPECT_NE(std::string(e.what()).find("bad_light.gltf"), std::string::npos) << e.what();
      EXPECT_NE(std::string(e.what()).find(needle), std::string::npos) << e.what();
    }
  }
}

}  // namespace
}  // namespace kestrel

namespace kestrel {
namespace {

// The light tree's probabilities: they sum to one at any point, sample() reports the same
// probability pmf() gives, and picks lights in those proportions.
TEST(LightTree, ProbabilitiesAreConsistentAndSumToOne) {
  test::Rng rng{5};
  std::vector<render::LightTree::Item> items;
  for (int i = 0; i < 300; ++i) {
    const Vec3 c = rng.in_box({-10, 0, -10}, {10, 3, 10});
    Bounds3 b;
    extend(b, c), extend(b, c + Vec3{0.1f, 0, 0.1f} * rng.uniform());
    items.push_back({b, i % 7 == 0 ? 0.0f : 1 + 100 * rng.uniform()});
  }
  render::LightTree tree;
  tree.build(items);
  for (int k = 0; k < 20; ++k) {
    const Vec3 x = rng.in_box({-12, 0, -12}, {12, 4, 12});
    double sum = 0;
    for (size_t i = 0; i < items.size(); ++i) sum += tree.pmf(x, i);
    EXPECT_NEAR(sum, 1.0, 1e-4);
    std::vector<int> count(items.size(), 0);
    const int n = 20000;
    for (int j = 0; j < n; ++j) {
      float p = 0;
      const size_t i = tree.sample(x, (float(j) + 0.5f) / float(n), p);
      ASSERT_LT(i, items.size());
      ASSERT_NEAR(p, tree.pmf(x, i), 1e-5f * std::max(1.0f, p));
      ASSERT_GT(items[i].power, 0.0f);  // zero-power lights are never picked
      ++count[i];
    }
    for (size_t i = 0; i < items.size(); ++i)  // stratified u: frequencies within a count or two
      EXPECT_NEAR(count[i], tree.pmf(x, i) * n, 2.5 + 0.02 * tree.pmf(x, i) * n) << i;
    // The walks of a batch (four at a time, any remainder) pick what single walks pick.
    for (size_t m : {size_t(1), size_t(3), size_t(4), size_t(9), size_t(37)}) {
      std::vector<float> u(m), pmf(m);
      std::vector<uint32_t> light(m);
      for (float& v : u) v = rng.uniform();
      tree.sample(x, u.data(), m, light.data(), pmf.data());
      for (size_t j = 0; j < m; ++j) {
        float p = 0;
        EXPECT_EQ(light[j], tree.sample(x, u[j], p)) << m << " " << j;
        EXPECT_EQ(pmf[j], p) << m << " " << j;
      }
    }
  }
}

// Unbiased both ways: the lamp hall converges to the same image with either light choice.
TEST(LightTree, TreeAndPowerSamplingConvergeToTheSameImage) {
  const Asset hall = Asset::load("builtin:lamp_hall");
  Renderer r(hall.scene());
  EXPECT_EQ(r.light_count(), 2048u);
  RenderSettings s;
  s.width = 32, s.height = 18, s.spp = 256, s.max_depth = 2;
  const Camera cam = *find_view(hall, "inside");
  double mean[2] = {0, 0};
  for (int m = 0; m < 2; ++m) {
    s.light_sampling = m ? LightSampling::tree : LightSampling::power;
    s.seed = uint64_t(m);
    const Frame f = r.render(cam, s);
    for (float v : f[Aov::color].pixels) mean[m] += v;
  }
  EXPECT_NEAR(mean[1] / mean[0], 1.0, 0.03);
}

}  // namespace
}  // namespace kestrel

namespace kestrel {
namespace {

// Lights files: what a user adds to a scene (data/lights/sponza_100.json); every bad light an
// error naming the file and the light; added lights survive an animated asset's updates.
TEST(Lights, LightsFilesLoadAndBadOnesNameFileAndLight) {
  const std::string good = test::write_temp_file("good.lights.json", R"({"lights": [
    {"name": "a", "type": "point", "position": [0, 0, -3], "intensity": 8},
    {"name": "b", "type": "spot", "position": [1, 2, 3], "direction": [0, -2, 0], "outer_cone": 0.5},
    {"type": "directional", "direction": [0, 0, -1], "color": [1, 0.5, 0.25], "intensity": 3}]})");
  const std::vector<Light> l = load_lights(good);
  ASSERT_EQ(l.size(), 3u);
  EXPECT_EQ(l[1].type, Light::Type::spot);
  EXPECT_FLOAT_EQ(l[1].direction.y, -1.0f);  // normalised
  EXPECT_EQ(l[2].name, "light2");
  Asset asset = Asset::from_scene(plane());
  asset.add_lights({l[0]});
  Renderer r(asset.scene(), Environment::parse("none"));
  RenderSettings s;
  s.width = s.height = 1, s.max_depth = 2, s.jitter = false;
  EXPECT_NEAR(r.render(Camera{{0, 0, 0}, {0, 0, -5}, 10}, s)[Aov::color].pixels[1],
              kAlbedo / kPi * 2.0f, 1e-4f);
  Asset animated = Asset::load(test::write_animated_gltf("lights_anim.gltf"));
  animated.add_lights(l);
  animated.update(1.0);
  EXPECT_EQ(animated.scene().lights().size(), 3u);
  for (
      const auto& [text, needle] : std::vector<std::pair<std::string, std::string>>{
          {R"({"lights": [{"name": "x", "type": "area"}]})", "unknown type 'area'"},
          {R"({"lights": [{"name": "neg", "intensity": -1}]})", "neg"},
          {R"({"lights": [{"name": "cone", "type": "spot", "direction": [0, 0, 1], "inner_cone": 1, "outer_cone": 0.5}]})",
           "cone"},
          {R"({"lights": [{"name": "dir", "type": "directional", "direction": [0, 0, 0]}]})",
           "direction"},
          {R"({"lights": [3]})", "light 0"},
          {R"({"light": []})", "\"lights\" array"},
          {R"({"lights": [{"position": [1, 2]}]})", "position"}}) {
    const std::string bad = test::write_temp_file("bad.lights.json", text);
    try {
      load_lights(bad);
      ADD_FAILURE() << needle;
    } catch (const Error& e) {
      EXPECT_NE(std::string(e.what()).find("bad.lights.json"), std::string::npos) << e.what();
      EXPECT_NE(std::string(e.what()).find(needle), std::string::npos) << e.what();
    }
  }
  EXPECT_THROW(load_lights("/nonexistent/x.lights.json"), Error);
}

}  // namespace
}  // namespace kestrel

namespace kestrel {
namespace {

// A views file's suggested lighting (what `kestrel run` / `view` use without lighting flags):
// read beside the scene, the shared Sponza's is the sun; bad entries name the file.
TEST(Lights, ViewsFilesSuggestLighting) {
  const std::filesystem::path dir =
      std::filesystem::temp_directory_path() / "kestrel_suggested_lighting";
  std::filesystem::create_directories(dir);
  auto with = [&](const std::string& lighting) {
    std::ofstream(dir / "room.views.json") << "{\"lighting\": " << lighting << ", \"views\": {}}";
    return suggested_lighting((dir / "room.obj").string());
  };
  const auto l = with(R"({"sun": "10,40,5", "sky": true})");
  ASSERT_TRUE(l.has_value());
  EXPECT_EQ(l->sun, "10,40,5");
  EXPECT_TRUE(l->sky);
  EXPECT_TRUE(l->env.empty());
  for (const char* bad : {R"("sun")", R"({"sun": 3})", R"({"sun": "0,120"})", R"({"sky": "yes"})",
                          R"({"lamp": 1})"}) {
    try {
      with(bad);
      ADD_FAILURE() << bad << " was accepted";
    } catch (const Error& e) {
      EXPECT_NE(std::string(e.what()).find("room.views.json"), std::string::npos) << e.what();
    }
  }
  std::filesystem::remove(dir / "room.views.json");
  EXPECT_FALSE(suggested_lighting((dir / "room.obj").string()).has_value());
  const auto sponza = suggested_lighting("dabrovic_sponza/sponza.obj");  // data/views
  ASSERT_TRUE(sponza.has_value());
  EXPECT_FALSE(sponza->sun.empty());
  EXPECT_FALSE(suggested_lighting("builtin:cornell_box").has_value());
}

}  // namespace
}  // namespace kestrel
