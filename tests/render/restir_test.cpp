// ReSTIR DI against independent oracles: closed forms where resampling one light must be
// exact (a point light, the sun), plain NEE's converged image for the unbiased mode (the lamp
// hall: 2 048 emitters behind 400 pillars), error that falls as reservoirs are reused frame
// after frame, the same bits for any thread count, and bad settings as clear errors.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>

#include "kestrel/kestrel.h"
#include "render/testing.h"
#include "support/oracles.h"

namespace kestrel {
namespace {

constexpr float kPi = 3.14159265358979f;
constexpr float kAlbedo = 0.5f;

// A 40 x 40 Lambertian plane at z = -5 facing +z.
Scene plane() {
  return test::lit_plane(kAlbedo, "test:restir_plane");
}

double mean(const FloatImage& img, int y0, int y1) {
  double sum = 0;
  for (int y = y0; y < y1; ++y)
    for (int x = 0; x < img.width * img.channels; ++x)
      sum += img.pixels[size_t(y * img.width * img.channels + x)];
  return sum / double((y1 - y0) * img.width * img.channels);
}

double relmse(const FloatImage& a, const FloatImage& ref) {
  double sum = 0;
  for (size_t i = 0; i < a.pixels.size(); ++i) {
    const double d = a.pixels[i] - ref.pixels[i];
    sum += d * d / (double(ref.pixels[i]) * ref.pixels[i] + 1e-2);
  }
  return sum / double(a.pixels.size());
}

RenderSettings restir_settings(DirectLighting d) {
  RenderSettings s;
  s.direct = d, s.max_depth = 2, s.light_sampling = LightSampling::tree;
  return s;
}

// One light and one surface: every candidate is the same light, so W = 1 / pdf and the
// reservoir's estimate is exact, with and without reuse.
TEST(Restir, OnePointLightIsExact) {
  Scene s = plane();
  s.lights.push_back(
      Light{.name = "bulb", .type = Light::Type::point, .position = {0, 0, -3}, .intensity = 8});
  const Asset asset = Asset::from_scene(std::move(s));
  for (DirectLighting d : {DirectLighting::restir, DirectLighting::restir_unbiased}) {
    Renderer r(asset.scene(), Environment::parse("none"));
    RenderSettings rs = restir_settings(d);
    rs.width = 8, rs.height = 8, rs.jitter = false;
    for (uint32_t f = 0; f < 3; ++f) {  // frame 0 alone, then with history
      rs.frame = f;
      const Frame out = r.render(Camera{{0, 0, 0}, {0, 0, -5}, 1}, rs);
      const float* c = out[Aov::color].at(4, 4);
      EXPECT_NEAR(c[1], kAlbedo / kPi * 2.0f, 1e-3f) << int(d) << " frame " << f;
    }
  }
}

TEST(Restir, SunGivesItsIrradiance) {
  Scene s = plane();  // turned into a floor at y = -5, facing +y, under the sun
  s.meshes[0].positions = {{-20, -5, 20}, {20, -5, 20}, {20, -5, -20}, {-20, -5, -20}};
  const Asset floor = Asset::from_scene(std::move(s));
  Environment env = Environment::parse("none");
  env.sun = Sun::parse("0,90,3");
  Renderer r(floor.scene(), env);
  RenderSettings rs = restir_settings(DirectLighting::restir);
  rs.width = 4, rs.height = 4, rs.jitter = false;
  for (uint32_t f = 0; f < 2; ++f) {
    rs.frame = f;
    const Frame out = r.render(Camera{{0, 0, 0}, {0, -5, 0.01f}, 1}, rs);
    // E = 3 on a surface facing the sun (its disk's 0.27 degrees change cos by < 1e-5).
    EXPECT_NEAR(out[Aov::color].at(2, 2)[1], kAlbedo / kPi * 3.0f, 1e-3f);
  }
}

// The unbiased mode converges to NEE's image where visibility matters (pillars between lamps
// and floor), and the biased mode stays close: the mean of 48 independent chains of 16
// passes (each pass reusing the one before), whole image and three bands of rows.
TEST(Restir, UnbiasedModeConvergesToNee) {
  const Asset hall = Asset::load("builtin:lamp_hall");
  const Camera cam = *find_view(hall, "inside");
  RenderSettings s;
  s.width = 32, s.height = 18, s.spp = 2048, s.max_depth = 2, s.seed = 3;
  s.light_sampling = LightSampling::tree, s.jitter = false;  // lamps seen directly alias
  Renderer nee(hall.scene());
  const Frame ref = nee.render(cam, s);
  for (DirectLighting d : {DirectLighting::restir_unbiased, DirectLighting::restir}) {
    FloatImage sum(32, 18, 3);
    std::fill(sum.pixels.begin(), sum.pixels.end(), 0.0f);
    for (uint64_t chain = 0; chain < 48; ++chain) {
      Renderer r(hall.scene());
      RenderSettings rs = s;
      rs.direct = d, rs.spp = 16, rs.seed = 100 + chain;
      const Frame f = r.render(cam, rs);
      for (size_t i = 0; i < sum.pixels.size(); ++i) sum.pixels[i] += f[Aov::color].pixels[i];
    }
    const bool unbiased = d == DirectLighting::restir_unbiased;
    for (int band = -1; band < 3; ++band) {
      const int y0 = band < 0 ? 0 : band * 6, y1 = band < 0 ? 18 : y0 + 6;
      const double ratio = mean(sum, y0, y1) / 48 / mean(ref[Aov::color], y0, y1);
      std::printf("%s band %d: mean / NEE's %.4f\n", unbiased ? "unbiased" : "biased", band, ratio);
      // biased: darker where reused pixels see other lamps than their own (measured 3 %)
      EXPECT_NEAR(ratio, 1.0, unbiased ? (band < 0 ? 0.025 : 0.04) : 0.08)
          << "unbiased " << unbiased << " band " << band;
    }
  }
}

// Reuse is what ReSTIR is for: a frame with 8 frames of history is much closer to the
// converged image than the first frame, and than a frame of plain NEE.
TEST(Restir, HistoryReducesTheErrorOfAFrame) {
  const Asset hall = Asset::load("builtin:lamp_hall");
  const Camera cam = *find_view(hall, "inside");
  RenderSettings s;
  s.width = 128, s.height = 72, s.spp = 512, s.max_depth = 2, s.seed = 5;
  s.light_sampling = LightSampling::tree, s.jitter = false;
  Renderer nee(hall.scene());
  const Frame ref = nee.render(cam, s);
  s.spp = 1;
  const double one_nee = relmse(nee.render(cam, s)[Aov::color], ref[Aov::color]);
  Renderer r(hall.scene());
  s.direct = DirectLighting::restir;
  double first = 0, last = 0;
  for (uint32_t f = 0; f <= 8; ++f) {
    s.frame = f, s.seed = 40 + f;
    const double e = relmse(r.render(cam, s)[Aov::color], ref[Aov::color]);
    (f == 0 ? first : last) = e;
  }
  std::printf("relMSE: NEE 1 spp %.4f, ReSTIR frame 0 %.4f, frame 8 %.4f\n", one_nee, first, last);
  EXPECT_LT(first, one_nee);     // 8 resampled candidates beat one sample
  EXPECT_LT(last, 0.5 * first);  // temporal and spatial reuse
  EXPECT_LT(last, 0.25 * one_nee);
}

TEST(Restir, SameBitsForAnyThreadCountAndFreshAtFrameZero) {
  const Asset hall = Asset::load("builtin:lamp_hall");
  const Camera cam = *find_view(hall, "inside");
  auto sequence = [&](int threads) {
    Renderer r(hall.scene());
    RenderSettings s = restir_settings(DirectLighting::restir);
    s.width = 80, s.height = 45, s.threads = threads, s.max_depth = 3;
    std::vector<float> out;
    for (uint32_t f = 0; f < 3; ++f) {
      s.frame = f;
      const Frame fr = r.render(cam, s);
      out.insert(out.end(), fr[Aov::color].pixels.begin(), fr[Aov::color].pixels.end());
    }
    s.frame = 0;  // frame 0 again: no history, the first frame's bits
    const Frame again = r.render(cam, s);
    EXPECT_TRUE(
        std::equal(again[Aov::color].pixels.begin(), again[Aov::color].pixels.end(), out.begin()));
    return out;
  };
  EXPECT_EQ(sequence(1), sequence(2));
}

// The target the candidates resample by (its tests on the sample combined, not taken one by
// one) is the luminance of the full evaluation reuse and shading use, to the bit: emissive
// triangles (the lamp hall), point and spot lights, the sun and the sky.
TEST(Restir, CandidatesTargetIsTheFullEvaluationsLuminance) {
  Scene spots = plane();
  spots.lights.push_back(
      Light{.name = "bulb", .type = Light::Type::point, .position = {0, 2, -3}, .intensity = 8});
  spots.lights.push_back(Light{.name = "spot",
                               .type = Light::Type::spot,
                               .position = {1, 3, 0},
                               .direction = {0, -0.70710678f, -0.70710678f},
                               .intensity = 20});
  const Asset hall = Asset::load("builtin:lamp_hall");
  const Asset lamps = Asset::from_scene(spots);
  for (const Asset* a : {&hall, &lamps}) {
    Renderer renderer(a->scene(), make_lighting("", "30,40", true));
    RenderSettings s = restir_settings(DirectLighting::restir);
    s.width = 16, s.height = 8;
    renderer.render(Camera{}, s);  // the lights as a render sets them up
    const std::array<size_t, 2> check = RendererTesting::restir_target_check(renderer, 20000, 7);
    EXPECT_EQ(check[0], 0u) << a->source();
    EXPECT_GT(check[1], 2000u) << a->source();  // enough lit samples to mean something
  }
}

TEST(Restir, BadSettingsAreErrors) {
  const Asset hall = Asset::load("builtin:lamp_hall");
  Renderer r(hall.scene());
  RenderSettings s = restir_settings(DirectLighting::restir);
  s.width = 8, s.height = 8;
  const Camera cam = *find_view(hall, "inside");
  s.restir_candidates = 0;
  EXPECT_THROW(r.render(cam, s), Error);
  s.restir_candidates = 8, s.restir_neighbors = 17;
  EXPECT_THROW(r.render(cam, s), Error);
  EXPECT_EQ(direct_lighting_from_name("restir-unbiased"), DirectLighting::restir_unbiased);
  EXPECT_EQ(direct_lighting_from_name("ris"), std::nullopt);
}

}  // namespace
}  // namespace kestrel

namespace kestrel {
namespace {

// Temporal reuse follows the motion vectors: under a turning camera (3 degrees a frame, ~4
// pixels), with spatial reuse off, frame 8 is far closer to its converged image than frame
// 0, and closer than when the renderer is not told the previous camera (history looked up
// at the same pixel, much of it then rejected or from another surface).
TEST(Restir, HistoryFollowsAMovingCamera) {
  const Asset hall = Asset::load("builtin:lamp_hall");
  const Camera start = *find_view(hall, "inside");
  auto camera_at = [&](uint32_t f) {
    Camera c = start;
    const Vec3 d = c.target - c.eye;
    const float a = 0.0523599f * float(f), ca = std::cos(a), sa = std::sin(a);
    c.target = c.eye + Vec3{ca * d.x + sa * d.z, d.y, -sa * d.x + ca * d.z};
    return c;
  };
  RenderSettings s;
  s.width = 96, s.height = 54, s.max_depth = 2, s.jitter = false;
  s.light_sampling = LightSampling::tree;
  s.direct = DirectLighting::restir, s.restir_neighbors = 0;
  Renderer nee(hall.scene());
  RenderSettings rs = s;
  rs.direct = DirectLighting::nee, rs.spp = 384, rs.seed = 1;
  const Frame ref0 = nee.render(camera_at(0), rs), ref8 = nee.render(camera_at(8), rs);
  double err[2][2] = {{0, 0}, {0, 0}};  // [told the previous camera][frame 0, 8]
  for (int told = 0; told < 2; ++told) {
    Renderer r(hall.scene());
    std::optional<Camera> prev;
    for (uint32_t f = 0; f <= 8; ++f) {
      s.frame = f, s.seed = 60 + f;
      const Camera cam = camera_at(f);
      const Frame fr = r.render(cam, s, told ? prev : std::nullopt);
      prev = cam;
      if (f == 0) err[told][0] = relmse(fr[Aov::color], ref0[Aov::color]);
      if (f == 8) err[told][1] = relmse(fr[Aov::color], ref8[Aov::color]);
    }
  }
  std::printf(
      "turning camera, temporal reuse only: relMSE frame 0 %.4f, frame 8 %.4f (without "
      "the previous camera %.4f)\n",
      err[1][0], err[1][1], err[0][1]);
  EXPECT_LT(err[1][1], 0.5 * err[1][0]);
  EXPECT_LT(err[1][1], 0.8 * err[0][1]);
}

}  // namespace
}  // namespace kestrel
