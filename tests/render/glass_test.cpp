// Glass. The glass lobe (render/bsdf.h) against its own pdf over the whole sphere and against
// optics in double precision: chi-square tests of sampling above and below the surface, eval /
// pdf / sample agreement, Snell's law and the exact Fresnel split at a smooth interface, and
// the flux a rough interface passes on (reflected plus eta^2 x transmitted radiance) at most 1.
// The renderer against closed forms: a clear glass sphere in a uniform environment is
// invisible (every path's radiance scale undone on the way out), a pane seen head-on is
// F0 + (1 - F0) x its tint, and a slab of absorbing glass lets exp(-sigma d) through.
#include <gtest/gtest.h>

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <random>
#include <vector>

#include "kestrel/kestrel.h"
#include "render/bsdf_sampling.h"
#include "support/oracles.h"
#include "support/scene_renderer.h"

namespace kestrel::render {
namespace {

using test::SceneRenderer;

// Fresnel reflectance of unpolarised light, in double precision: n1 on the incident side.
double fresnel_reference(double cos_i, double n1, double n2) {
  const double sin_t = n1 / n2 * std::sqrt(std::max(0.0, 1 - cos_i * cos_i));
  if (sin_t >= 1) return 1;
  const double cos_t = std::sqrt(1 - sin_t * sin_t);
  const double rs = (n1 * cos_i - n2 * cos_t) / (n1 * cos_i + n2 * cos_t);
  const double rp = (n2 * cos_i - n1 * cos_t) / (n2 * cos_i + n1 * cos_t);
  return 0.5 * (rs * rs + rp * rp);
}

struct Case {
  const char* name;
  BsdfParams p;
};

std::vector<Case> cases() {
  auto make = [](Vec3 base, float metallic, float roughness, float specular, float transmission,
                 float eta, bool thin) {
    BsdfParams p;
    p.base = base, p.metallic = metallic, p.alpha = std::max(roughness * roughness, min_alpha),
    p.specular = specular, p.transmission = transmission, p.eta = eta, p.thin = thin;
    return p;
  };
  return {{"entering", make({1, 1, 1}, 0, 0.5f, 1, 1, 1.5f, false)},
          {"leaving", make({0.9f, 0.95f, 1}, 0, 0.5f, 1, 1, 1 / 1.5f, false)},
          {"diamond", make({1, 1, 1}, 0, 0.35f, 0, 1, 2.42f, false)},
          {"thin_tinted", make({0.2f, 0.7f, 0.4f}, 0, 0.45f, 1, 1, 1.5f, true)},
          {"half_glass", make({0.6f, 0.5f, 0.4f}, 0.2f, 0.6f, 1, 0.5f, 1.33f, false)}};
}

class GlassCase : public ::testing::TestWithParam<std::tuple<int, float>> {};

TEST_P(GlassCase, SamplingMatchesPdfOverTheSphere) {
  const auto [index, cos_o] = GetParam();
  const Case c = cases()[size_t(index)];
  const Vec3 wo{std::sqrt(1 - cos_o * cos_o), 0, cos_o};
  const SamplingCheck r = expect_sampling_matches_pdf(c.p, wo, true, 16, 4321u + unsigned(index),
                                                      fmt::format("{} cos_o {}", c.name, cos_o));
  EXPECT_LE(r.total, 1.002) << c.name << ": the pdf integrates to more than 1";
  EXPECT_GE(r.total, 0.9) << c.name << ": the pdf misses directions the sampling reaches";
  EXPECT_GT(r.below, c.p.eta > 1 ? 100'000 : 20'000) << c.name << ": little goes through";
}

TEST_P(GlassCase, EvalPdfAndSampleAgree) {
  const auto [index, cos_o] = GetParam();
  const Case c = cases()[size_t(index)];
  const Vec3 wo{std::sqrt(1 - cos_o * cos_o), 0, cos_o};
  std::mt19937 gen(7);
  std::uniform_real_distribution<float> u(0.0f, 0x1.fffffep-1f);
  int through = 0;
  for (int s = 0; s < 4000; ++s) {
    BsdfSample bs;
    if (!bsdf_sample(c.p, wo, u(gen), u(gen), u(gen), bs)) continue;
    through += bs.wi.z < 0;
    const float pdf = bsdf_pdf(c.p, wo, bs.wi);
    const Vec3 f = bsdf_eval(c.p, wo, bs.wi);
    ASSERT_NEAR(bs.pdf, pdf, 1e-5f * pdf) << c.name;
    for (int k = 0; k < 3; ++k)
      ASSERT_NEAR(bs.weight[k], f[k] / pdf, 1e-4f * (1 + f[k] / pdf)) << c.name;
    if (c.p.thin || bs.wi.z > 0) {  // reciprocal (a refraction's radiance scales by eta^2)
      const Vec3 fr = bsdf_eval(c.p, bs.wi, wo);
      const float ci = std::fabs(bs.wi.z);
      if (bs.wi.z > 0)
        for (int k = 0; k < 3; ++k)
          ASSERT_NEAR(f[k] / ci, fr[k] / wo.z, 2e-4f * (1 + f[k] / ci)) << c.name;
    }
  }
  EXPECT_GT(through, c.p.eta > 1 ? 400 : 80) << c.name;
}

// Flux: what a rough interface reflects plus what it transmits (radiance x eta^2, the solid
// angle's change) is at most what arrives, and, for white glass, most of it (single
// scattering loses only what the masking term drops).
TEST_P(GlassCase, PassesOnNoMoreFluxThanItReceives) {
  const auto [index, cos_o] = GetParam();
  const Case c = cases()[size_t(index)];
  const Vec3 wo{std::sqrt(1 - cos_o * cos_o), 0, cos_o};
  constexpr int nt = 1024, np = 256;
  double reflected[3] = {}, transmitted[3] = {};
  for (int i = 0; i < nt; ++i)
    for (int j = 0; j < np; ++j) {
      const double t = (i + 0.5) * pi / nt, ph = (j + 0.5) * 2 * pi / np;
      const Vec3 f = bsdf_eval(c.p, wo, dir(t, ph));
      const double w = std::sin(t) * (pi / nt) * (2 * pi / np);
      for (int k = 0; k < 3; ++k) (t < pi / 2 ? reflected : transmitted)[k] += f[k] * w;
    }
  const double eta2 = c.p.thin ? 1.0 : double(c.p.eta) * c.p.eta;
  for (int k = 0; k < 3; ++k) {
    const double flux = reflected[k] + eta2 * transmitted[k];
    EXPECT_LE(flux, 1.01) << c.name << " channel " << k;
    if (c.p.transmission == 1 && c.p.base[k] == 1)
      EXPECT_GT(flux, cos_o > 0.3f ? 0.8 : 0.7) << c.name << " channel " << k;
  }
}

INSTANTIATE_TEST_SUITE_P(All, GlassCase,
                         ::testing::Combine(::testing::Range(0, 5),
                                            ::testing::Values(0.9f, 0.5f, 0.15f)));

TEST(Glass, FresnelIsTheExactDielectricOne) {
  EXPECT_NEAR(fresnel_dielectric(1, 1.5f), 0.04f, 1e-6f);
  for (double eta : {1.33, 1.5, 2.42, 1 / 1.5, 1 / 1.33})
    for (int i = 0; i <= 100; ++i) {
      const double c = i / 100.0;
      EXPECT_NEAR(fresnel_dielectric(float(c), float(eta)), fresnel_reference(c, 1, eta), 2e-6)
          << "eta " << eta << " cos " << c;
    }
  // Total internal reflection beyond the critical angle (sin > 1 / 1.5) leaving glass.
  EXPECT_EQ(fresnel_dielectric(0.7f, 1 / 1.5f), 1.0f);
}

// A smooth interface: every transmitted sample obeys Snell's law in the plane of incidence,
// every reflected one mirrors wo; the share reflected is the Fresnel reflectance; a
// refraction's weight is 1 / eta^2 (radiance), a thin sheet's its tint.
TEST(Glass, SmoothInterfaceRefractsBySnellsLaw) {
  for (const bool thin : {false, true})
    for (const double eta : {1.5, 1 / 1.5, 2.42}) {
      if (thin && eta < 1) continue;
      BsdfParams p;
      p.base = {1, 0.5f, 0.25f}, p.metallic = 0, p.specular = 1, p.alpha = min_alpha;
      p.transmission = 1, p.eta = float(eta), p.thin = thin;
      const double cos_i = 0.8;  // below the critical angle leaving glass (0.745)
      const Vec3 wo{float(std::sqrt(1 - cos_i * cos_i)), 0, float(cos_i)};
      std::mt19937 gen(11);
      std::uniform_real_distribution<float> u(0.0f, 0x1.fffffep-1f);
      int reflected = 0, transmitted = 0;
      std::vector<double> off;  // each sample's distance from the ideal direction
      constexpr int n = 20000;
      for (int s = 0; s < n; ++s) {
        BsdfSample bs;
        ASSERT_TRUE(bsdf_sample(p, wo, u(gen), u(gen), u(gen), bs));
        Vec3 ideal{-wo.x, 0, wo.z};
        if (bs.wi.z < 0) {
          ++transmitted;
          const double sin_t = std::sqrt(1 - cos_i * cos_i) / (thin ? 1.0 : eta);
          ideal = {-float(sin_t), 0, -float(std::sqrt(1 - sin_t * sin_t))};
          const double scale = thin ? 1.0 : 1.0 / (eta * eta);
          for (int k = 0; k < 3; ++k) EXPECT_NEAR(bs.weight[k], p.base[k] * scale, 0.02 * scale);
        } else {
          ++reflected;
        }
        off.push_back(length(bs.wi - ideal));
      }
      // GGX at alpha 1e-3 has long tails: most samples within a few thousandths.
      std::sort(off.begin(), off.end());
      EXPECT_LT(off[n / 2], 3e-3) << "eta " << eta << " thin " << thin;
      EXPECT_LT(off[n * 9 / 10], 0.012) << "eta " << eta << " thin " << thin;
      const double f = fresnel_reference(cos_i, 1, eta);
      const double se = std::sqrt(f * (1 - f) / n);
      EXPECT_NEAR(double(reflected) / n, f, 5 * se + 1e-3) << "eta " << eta << " thin " << thin;
      EXPECT_EQ(reflected + transmitted, n);
    }
}

// Without transmission the BSDF is the opaque one: nothing below the surface.
TEST(Glass, OpaqueMaterialsSendNothingBelow) {
  BsdfParams p;
  p.base = {0.5f, 0.5f, 0.5f}, p.specular = 1, p.alpha = 0.1f;
  const Vec3 wo = normalize(Vec3{0.3f, 0.1f, 0.9f});
  EXPECT_EQ(bsdf_pdf(p, wo, Vec3{0, 0.6f, -0.8f}), 0.0f);
  EXPECT_EQ(luminance(bsdf_eval(p, wo, Vec3{0, 0.6f, -0.8f})), 0.0f);
}

// ---- the renderer ----------------------------------------------------------------------------

TriangleMesh sphere(float radius, int rings, int segments) {
  TriangleMesh m;
  for (int i = 0; i <= rings; ++i)
    for (int j = 0; j <= segments; ++j) {
      const double t = pi * i / rings, p = 2 * pi * j / segments;
      m.positions.push_back(dir(t, p) * radius);
    }
  for (int i = 0; i < rings; ++i)
    for (int j = 0; j < segments; ++j) {
      const uint32_t a = uint32_t(i * (segments + 1) + j), b = a + 1,
                     d = a + uint32_t(segments + 1), e = d + 1;
      for (uint32_t k : {a, d, b, b, d, e}) m.indices.push_back(k);  // counter-clockwise outside
      m.material_ids.push_back(0), m.material_ids.push_back(0);
    }
  return m;
}

// An axis-aligned box [lo, hi], faces counter-clockwise seen from outside.
TriangleMesh box(Vec3 lo, Vec3 hi) {
  TriangleMesh m;
  for (int i = 0; i < 8; ++i)
    m.positions.push_back({i & 1 ? hi.x : lo.x, i & 2 ? hi.y : lo.y, i & 4 ? hi.z : lo.z});
  const uint32_t faces[6][4] = {{0, 4, 6, 2}, {1, 3, 7, 5}, {0, 1, 5, 4},
                                {2, 6, 7, 3}, {0, 2, 3, 1}, {4, 5, 7, 6}};
  for (const auto& f : faces) {
    for (uint32_t k : {f[0], f[1], f[2], f[0], f[2], f[3]}) m.indices.push_back(k);
    m.material_ids.push_back(0), m.material_ids.push_back(0);
  }
  return m;
}

double mean_green(const Frame& f, int x0, int y0, int x1, int y1) {
  double sum = 0;
  for (int y = y0; y < y1; ++y)
    for (int x = x0; x < x1; ++x) sum += f[Aov::color].at(x, y)[1];
  return sum / (double(x1 - x0) * (y1 - y0));
}

TEST(GlassRender, ClearSphereInAUniformEnvironmentIsInvisible) {
  for (const float roughness : {0.0f, 0.3f}) {
    Scene s;
    s.source = "test:glass_sphere";
    s.materials = {Material{.name = "glass",
                            .base_color = {1, 1, 1},
                            .roughness = roughness,
                            .specular = 1,
                            .transmission = 1,
                            .ior = 1.5f}};
    s.meshes.push_back(sphere(1, 48, 96));
    SceneRenderer r(std::move(s), Environment::parse("constant:1,1,1"));
    RenderSettings rs;
    rs.width = rs.height = 32, rs.spp = 64, rs.max_depth = 48;
    const Frame f = r.render(Camera{{0, 0, -3}, {0, 0, 0}, 40}, rs);
    const double inside = mean_green(f, 10, 10, 22, 22);  // within the sphere's disk
    // Smooth: every path ends in the environment with weight 1 (a refraction's 1 / eta^2
    // undone on the way out); rough: single-scattering microfacets lose a few per cent.
    if (roughness == 0)
      EXPECT_NEAR(inside, 1.0, 0.02);
    else
      EXPECT_TRUE(inside > 0.85 && inside < 1.01) << inside;
  }
}

// A smooth glass ball under the overcast sky, against a ray tracer in double precision on the
// exact sphere: each pixel's centre ray split at every surface by the Fresnel reflectance,
// refracted by Snell's law (the ball is a lens: the sky appears upside down in it).
double sky(const double d[3]) {
  return d[1] > 0 ? (1 + 2 * d[1]) / 3 : 0.1;
}
double ball_radiance(const double o[3], const double d[3], bool inside, int depth) {
  const double b = o[0] * d[0] + o[1] * d[1] + o[2] * d[2];
  const double c = o[0] * o[0] + o[1] * o[1] + o[2] * o[2] - 1, disc = b * b - c;
  if (depth > 16 || disc < 0) return depth > 16 ? 0 : sky(d);
  const double t = inside ? -b + std::sqrt(disc) : -b - std::sqrt(disc);
  if (t <= 1e-9) return sky(d);
  double p[3], n[3];
  for (int k = 0; k < 3; ++k) p[k] = o[k] + t * d[k], n[k] = inside ? -p[k] : p[k];
  const double cos_i = -(d[0] * n[0] + d[1] * n[1] + d[2] * n[2]);
  const double n1 = inside ? 1.5 : 1.0, n2 = inside ? 1.0 : 1.5, eta = n2 / n1;
  const double f = fresnel_reference(cos_i, n1, n2);
  double r[3];
  for (int k = 0; k < 3; ++k) r[k] = d[k] + 2 * cos_i * n[k];
  double out = f * ball_radiance(p, r, inside, depth + 1);
  if (f < 1) {
    const double cos_t = std::sqrt(1 - (1 - cos_i * cos_i) / (eta * eta));
    double tr[3];
    for (int k = 0; k < 3; ++k) tr[k] = d[k] / eta + (cos_i / eta - cos_t) * n[k];
    out += (1 - f) / (eta * eta) * ball_radiance(p, tr, !inside, depth + 1);
  }
  return out;
}

TEST(GlassRender, BallLensMatchesAnExactRayTracer) {
  Scene s;
  s.source = "test:glass_ball";
  s.materials = {Material{.name = "glass",
                          .base_color = {1, 1, 1},
                          .roughness = 0,
                          .specular = 1,
                          .transmission = 1,
                          .ior = 1.5f}};
  TriangleMesh ball = sphere(1, 96, 192);
  ball.normals = ball.positions;  // unit sphere: the exact normals
  s.meshes.push_back(ball);
  SceneRenderer r(std::move(s), Environment::parse("sky"));
  RenderSettings rs;
  constexpr int w = 20;
  rs.width = rs.height = w, rs.spp = 1024, rs.max_depth = 24, rs.jitter = false;
  const Frame f = r.render(Camera{{0, 0, -3}, {0, 0, 0}, 45}, rs);
  // The renderer's pinhole (CameraModel): forward +z, right -x, up +y; pixel centres.
  const double tan_half = std::tan(22.5 * pi / 180);
  double abs_error = 0, error = 0, spread = 0;
  for (int y = 0; y < w; ++y)
    for (int x = 0; x < w; ++x) {
      const double sx = (2 * (x + 0.5) / w - 1) * tan_half, sy = (1 - 2 * (y + 0.5) / w) * tan_half;
      double d[3] = {-sx, sy, 1};
      const double len = std::sqrt(d[0] * d[0] + d[1] * d[1] + 1);
      for (double& v : d) v /= len;
      const double o[3] = {0, 0, -3};
      const double want = ball_radiance(o, d, false, 0);
      const double got = f[Aov::color].at(x, y)[1];
      abs_error += std::fabs(got - want), error += got - want, spread += std::fabs(want - 0.5);
    }
  const double n = double(w) * w;
  EXPECT_LT(abs_error / n, 0.01) << "mean error " << error / n;  // 0.0023 when written
  EXPECT_LT(std::fabs(error / n), 0.005);
  EXPECT_GT(spread / n, 0.1);  // the image has contrast to get wrong
}

// A 10 x 10 quad at z = 0 of one material seen head-on from (0, 0, -3) in a uniform
// environment of 1: the one pixel's colour.
Vec3 head_on(const Material& material, int spp) {
  Scene s;
  s.source = "test:head_on";
  s.materials = {material};
  TriangleMesh m;
  m.positions = {{-5, -5, 0}, {5, -5, 0}, {5, 5, 0}, {-5, 5, 0}};
  m.indices = {0, 1, 2, 0, 2, 3};
  m.material_ids = {0, 0};
  s.meshes.push_back(m);
  SceneRenderer r(std::move(s), Environment::parse("constant:1,1,1"));
  RenderSettings rs;
  rs.width = rs.height = 1, rs.spp = spp, rs.max_depth = 8, rs.jitter = false;
  const Frame f = r.render(Camera{{0, 0, -3}, {0, 0, 0}, 1}, rs);
  return {f[Aov::color].pixels[0], f[Aov::color].pixels[1], f[Aov::color].pixels[2]};
}

TEST(GlassRender, PaneSeenHeadOnIsFresnelPlusItsTint) {
  const Vec3 tint{0.2f, 0.5f, 0.9f};
  const Vec3 c = head_on(Material{.name = "pane",
                                  .base_color = tint,
                                  .roughness = 0,
                                  .specular = 1,
                                  .transmission = 1,
                                  .ior = 1.5f,
                                  .thin_walled = true},
                         4096);
  for (int k = 0; k < 3; ++k)  // F0 = 0.04 reflects the environment behind the camera
    EXPECT_NEAR(c[k], 0.04 + 0.96 * tint[k], 0.01) << "channel " << k;
}

// The opaque dielectric coat's reflectance follows the IOR too (glTF KHR_materials_ior): a
// black, smooth coated quad seen head-on in a uniform environment is ((ior - 1) / (ior + 1))^2.
TEST(GlassRender, CoatReflectsFresnelOfItsIor) {
  for (const float ior : {1.5f, 2.0f, 1.33f}) {
    const Vec3 c = head_on(
        Material{
            .name = "lacquer", .base_color = {0, 0, 0}, .roughness = 0, .specular = 1, .ior = ior},
        256);
    const double r0 = (ior - 1.0) / (ior + 1.0);
    EXPECT_NEAR(c.y, r0 * r0, 0.002) << "ior " << ior;
  }
}

TEST(GlassRender, AbsorbingSlabLetsThroughExpOfMinusSigmaD) {
  // A 2-thick slab of glass keeping (0.5, 0.8, 1) per unit length, seen head-on against a
  // uniform environment: what comes through is T^2 / (1 - R^2 a^2) x a (the slab's inner
  // reflections) with a = exp(-sigma 2), T = 1 - R, R = 0.04, plus R from the front face
  // and R T^2 a^2 / (1 - R^2 a^2) returned from the back face.
  const Vec3 keep{0.5f, 0.8f, 1.0f};
  Scene s;
  s.source = "test:glass_slab";
  Material glass{.name = "slab",
                 .base_color = {1, 1, 1},
                 .roughness = 0,
                 .specular = 1,
                 .transmission = 1,
                 .ior = 1.5f};
  glass.attenuation_color = keep, glass.attenuation_distance = 1;
  s.materials = {glass};
  s.meshes.push_back(box({-50, -50, -1}, {50, 50, 1}));
  SceneRenderer r(std::move(s), Environment::parse("constant:1,1,1"));
  RenderSettings rs;
  rs.width = rs.height = 1, rs.spp = 8192, rs.max_depth = 24, rs.jitter = false;
  const Frame f = r.render(Camera{{0, 0, -5}, {0, 0, 0}, 1}, rs);
  for (int k = 0; k < 3; ++k) {
    const double R = 0.04, T = 1 - R, a = std::pow(double(keep[k]), 2.0);
    const double through = T * T * a / (1 - R * R * a * a),
                 back = R * T * T * a * a / (1 - R * R * a * a);
    EXPECT_NEAR(f[Aov::color].pixels[size_t(k)], R + through + back, 0.01) << "channel " << k;
  }
}

TEST(GlassRender, BadGlassIsRefusedByName) {
  for (const int which : {0, 1, 2}) {
    Scene s;
    s.source = "test:bad_glass";
    Material m{.name = "crystal", .transmission = 1};
    if (which == 0) m.ior = 0.5f;
    if (which == 1) m.transmission = NAN;
    if (which == 2) m.attenuation_distance = -1;
    s.materials = {m};
    s.meshes.push_back(box({0, 0, 0}, {1, 1, 1}));
    try {
      SceneRenderer r(std::move(s), Environment::parse("none"));
      ADD_FAILURE() << "accepted case " << which;
    } catch (const Error& e) {
      EXPECT_NE(std::string(e.what()).find("crystal"), std::string::npos) << e.what();
    }
  }
}

}  // namespace
}  // namespace kestrel::render
