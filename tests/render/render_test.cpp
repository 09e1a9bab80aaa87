// The renderer against analytic answers: furnaces (closed emitting box, white sphere in a
// constant environment, constant environment image), AOVs on a plane and a sphere computed
// from the camera model in docs/renderer.md, motion vectors for a moving camera and a moving
// instance, EXR/PFM round trips and bad input (identical bits: determinism_test.cpp).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>

#include "kestrel/render.h"
#include "render/testing.h"
#include "support/oracles.h"
#include "support/scene_renderer.h"

namespace kestrel {
namespace {

using test::SceneRenderer;

constexpr float kPi = 3.14159265358979f;

Vec3 sub(Vec3 a, Vec3 b) {
  return {a.x - b.x, a.y - b.y, a.z - b.z};
}
Vec3 add(Vec3 a, Vec3 b) {
  return {a.x + b.x, a.y + b.y, a.z + b.z};
}
Vec3 mul(Vec3 a, float s) {
  return {a.x * s, a.y * s, a.z * s};
}
float dot3(Vec3 a, Vec3 b) {
  return a.x * b.x + a.y * b.y + a.z * b.z;
}
Vec3 cross3(Vec3 a, Vec3 b) {
  return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x};
}
Vec3 unit(Vec3 a) {
  return mul(a, 1.0f / std::sqrt(dot3(a, a)));
}

// The pinhole model of docs/renderer.md, written again here as the oracle.
struct Pinhole {
  Vec3 eye, f, r, u;
  float th, aspect;
  int w, h;
  Pinhole(const Camera& c, int w_, int h_) : w(w_), h(h_) {
    eye = c.eye;
    f = unit(sub(c.target, c.eye));
    r = unit(cross3(f, {0, 1, 0}));
    u = cross3(r, f);
    th = std::tan(c.vfov_degrees * kPi / 360.0f);
    aspect = float(w_) / float(h_);
  }
  Vec3 dir(float fx, float fy) const {
    const float sx = (2 * fx / w - 1) * th * aspect, sy = (1 - 2 * fy / h) * th;
    return unit(add(f, add(mul(r, sx), mul(u, sy))));
  }
  void project(Vec3 p, float& fx, float& fy) const {
    const Vec3 d = sub(p, eye);
    const float z = dot3(d, f);
    fx = (dot3(d, r) / (z * th * aspect) + 1) * 0.5f * w;
    fy = (1 - dot3(d, u) / (z * th)) * 0.5f * h;
  }
};

void add_quad(TriangleMesh& m, Vec3 a, Vec3 b, Vec3 c, Vec3 d, uint32_t material) {
  const uint32_t base = uint32_t(m.positions.size());
  for (Vec3 p : {a, b, c, d}) m.positions.push_back(p);
  for (uint32_t i : {0u, 1u, 2u, 0u, 2u, 3u}) m.indices.push_back(base + i);
  m.material_ids.push_back(material), m.material_ids.push_back(material);
}

Scene plane_scene(float z, Material mat) {
  Scene s;
  s.source = "test:plane";
  s.materials = {mat};
  TriangleMesh m;
  add_quad(m, {-20, -20, z}, {20, -20, z}, {20, 20, z}, {-20, 20, z}, 0);
  s.meshes.push_back(m);
  return s;
}

// A UV sphere with exact normals (for AOVs) or without (flat, for furnaces).
TriangleMesh uv_sphere(Vec3 c, float radius, int rings, int segments, bool normals) {
  TriangleMesh m;
  for (int i = 0; i <= rings; ++i)
    for (int j = 0; j <= segments; ++j) {
      const float t = kPi * float(i) / float(rings), p = 2 * kPi * float(j) / float(segments);
      const Vec3 n{std::sin(t) * std::cos(p), std::cos(t), std::sin(t) * std::sin(p)};
      m.positions.push_back(add(c, mul(n, radius)));
      if (normals) m.normals.push_back(n);
    }
  for (int i = 0; i < rings; ++i)
    for (int j = 0; j < segments; ++j) {
      const uint32_t a = uint32_t(i * (segments + 1) + j), b = a + 1,
                     d = a + uint32_t(segments + 1), e = d + 1;
      for (uint32_t k : {a, d, b, b, d, e}) m.indices.push_back(k);
      m.material_ids.push_back(0), m.material_ids.push_back(0);
    }
  return m;
}

double mean_of(const FloatImage& img, int channel) {
  double s = 0;
  for (int y = 0; y < img.height; ++y)
    for (int x = 0; x < img.width; ++x) s += img.at(x, y)[channel];
  return s / (double(img.width) * img.height);
}

// Mean and its standard error over pixels (pixels are independent estimates).
void mean_and_error(const FloatImage& img, int channel, double& mean, double& se) {
  mean = mean_of(img, channel);
  double v = 0;
  const double n = double(img.width) * img.height;
  for (int y = 0; y < img.height; ++y)
    for (int x = 0; x < img.width; ++x)
      v += (img.at(x, y)[channel] - mean) * (img.at(x, y)[channel] - mean);
  se = std::sqrt(v / (n - 1) / n);
}

// A closed box whose walls all emit Le = 1 and reflect rho = 0.5 (Lambertian): the radiance
// is 1 / (1 - 0.5) = 2 everywhere inside. `furnace_camera` looks at it from inside.
SceneRenderer furnace_box() {
  Scene s;
  s.source = "test:furnace_box";
  s.materials = {Material{.name = "wall", .base_color = {0.5f, 0.5f, 0.5f}, .emission = {1, 1, 1}}};
  s.meshes.push_back(test::closed_box({-1, -1, -1}, {1, 1, 1}).meshes[0]);
  s.meshes[0].material_ids.assign(s.meshes[0].triangle_count(), 0);
  return SceneRenderer(std::move(s), Environment::parse("none"));
}
const Camera furnace_camera{{0.2f, 0.1f, -0.3f}, {0.5f, 0.3f, 0.8f}, 80};

TEST(Furnace, ClosedEmittingBoxConvergesToLeOverOneMinusAlbedo) {
  // Exercises area-light NEE, MIS with BSDF hits, Russian roulette.
  SceneRenderer r = furnace_box();
  RenderSettings rs;
  rs.width = 48, rs.height = 48, rs.spp = 32, rs.max_depth = 64;
  const Frame f = r.render(furnace_camera, rs);
  for (int c = 0; c < 3; ++c) {
    double mean, se;
    mean_and_error(f[Aov::color], c, mean, se);
    EXPECT_NEAR(mean, 2.0, 0.005 * 2.0) << "channel " << c << " (standard error " << se << ")";
    EXPECT_LT(se, 0.002 * 2.0) << "too few samples for a 0.5 % test";
  }
}

// RenderSettings::indirect_rate: Russian roulette at the first bounce, stratified over the
// image, keeps the estimate unbiased — the furnace box's radiance is still 2 everywhere —
// and traces the asked share of bounce rays; the same bits for any thread count.
TEST(Furnace, FirstBounceAtAQuarterOrHalfRateStaysUnbiased) {
  SceneRenderer r = furnace_box();
  const Camera& cam = furnace_camera;
  RenderSettings rs;
  rs.width = 48, rs.height = 48, rs.spp = 64, rs.max_depth = 64;
  const uint64_t all = r.render(cam, rs).stats.bounce_rays;
  for (float rate : {0.5f, 0.25f}) {
    rs.indirect_rate = rate;
    rs.threads = 1;
    const Frame f = r.render(cam, rs);
    for (int c = 0; c < 3; ++c) {
      double mean, se;
      mean_and_error(f[Aov::color], c, mean, se);
      EXPECT_NEAR(mean, 2.0, 0.005 * 2.0)
          << "rate " << rate << " channel " << c << " (se " << se << ")";
    }
    // Every pixel's first hit traces a bounce in `rate` of its passes; a surviving path's
    // weight is 1 / rate, so the later Russian roulette (kept with probability min(0.95,
    // throughput)) keeps it a little longer: the bounce rays scale by a little over `rate`
    // (0.555 and 0.333 here).
    const double share = double(f.stats.bounce_rays) / double(all);
    EXPECT_GT(share, rate) << "rate " << rate;
    EXPECT_LT(share, rate + 0.1) << "rate " << rate;
    rs.threads = 2;
    EXPECT_EQ(f[Aov::color].pixels, r.render(cam, rs)[Aov::color].pixels) << "rate " << rate;
  }
}

TEST(Furnace, WhiteSphereInConstantEnvironmentIsInvisible) {
  // rho = 1 Lambertian convex object under a uniform environment of 1: every pixel is 1.
  for (const char* env : {"constant:1,1,1", "image"}) {
    Scene s;
    s.source = "test:white_sphere";
    s.materials = {Material{.name = "white", .base_color = {1, 1, 1}}};
    s.meshes.push_back(uv_sphere({0, 0, 0}, 1, 48, 96, false));
    Environment e;
    if (std::string(env) == "image") {
      FloatImage img(32, 16, 3);
      for (float& v : img.pixels) v = 1;
      const std::string path = test::write_temp_file("env_ones.pfm", "");
      write_pfm(path, img);
      e = Environment::parse(path);
    } else {
      e = Environment::parse(env);
    }
    SceneRenderer r(std::move(s), e);
    RenderSettings rs;
    rs.width = 48, rs.height = 48, rs.spp = 32;
    const Frame f = r.render(Camera{{0, 0, -3}, {0, 0, 0}, 50}, rs);
    double mean, se;
    mean_and_error(f[Aov::color], 1, mean, se);
    EXPECT_NEAR(mean, 1.0, 0.005) << env << " (standard error " << se << ")";
    // The sphere's own pixels, alone.
    double sum = 0;
    int n = 0;
    for (int y = 16; y < 32; ++y)
      for (int x = 16; x < 32; ++x) sum += f[Aov::color].at(x, y)[1], ++n;
    EXPECT_NEAR(sum / n, 1.0, 0.01) << env;
  }
}

// A white Lambertian plane y = 0 facing +Y, seen from above: its mean radiance.
double white_plane_radiance(const Environment& env) {
  Scene s = plane_scene(0, Material{.name = "white", .base_color = {1, 1, 1}});
  for (Vec3& p : s.meshes[0].positions) std::swap(p.y, p.z);
  SceneRenderer r(std::move(s), env);
  RenderSettings rs;
  rs.width = 48, rs.height = 48, rs.spp = 32;
  const Frame f = r.render(Camera{{0, 1, 0.01f}, {0, 0, 0}, 60}, rs);
  double mean, se;
  mean_and_error(f[Aov::color], 0, mean, se);
  EXPECT_LT(se, 0.001) << "too few samples for a 0.5 % test";
  return mean;
}

TEST(Furnace, WhitePlaneUnderTheOvercastSky) {
  // Irradiance of an up-facing plane under L = (1 + 2 cos theta) / 3: E / pi = 7/9, so a
  // white Lambertian plane has radiance 7/9 everywhere (no interreflection on a plane).
  EXPECT_NEAR(white_plane_radiance(Environment::parse("sky")), 7.0 / 9.0, 0.005 * 7.0 / 9.0);
}

TEST(Furnace, SkyAsAnImageMatchesTheAnalyticSky) {
  // The same overcast sky written as a 256 x 128 equirectangular image: exercises the image
  // environment's importance sampling and pdf (MIS weights) with a non-constant image.
  FloatImage img(256, 128, 3);
  for (int y = 0; y < img.height; ++y) {
    const float c = std::cos(kPi * (float(y) + 0.5f) / float(img.height));
    for (int x = 0; x < img.width; ++x)
      for (int k = 0; k < 3; ++k) img.at(x, y)[k] = c > 0 ? (1 + 2 * c) / 3 : 0.1f;
  }
  const std::string path = test::write_temp_file("overcast.pfm", "");
  write_pfm(path, img);
  EXPECT_NEAR(white_plane_radiance(Environment::parse(path)), 7.0 / 9.0, 0.005 * 7.0 / 9.0);
}

TEST(Cameras, ThinLensIsSharpOnlyAtItsFocusDistance) {
  // A checker-textured plane at distance 5. Through a thin lens focused at 5, every ray of a
  // pixel meets the plane where the pinhole ray does: the albedo AOV equals the pinhole
  // one. Focused at 2, the lens rays spread over the plane and the albedo blurs.
  Material mat{.name = "checker", .base_color = {1, 1, 1}};
  mat.base_color_texture = 0;
  Scene base = plane_scene(-5, mat);
  base.meshes[0].uvs = {{0, 0}, {8, 0}, {8, 8}, {0, 8}};
  Texture tex;
  tex.width = tex.height = 8;
  for (int y = 0; y < 8; ++y)
    for (int x = 0; x < 8; ++x)
      for (int c = 0; c < 4; ++c) tex.rgba.push_back((x + y) % 2 ? 255 : 0);
  base.textures = {tex};
  SceneRenderer r(base, Environment::parse("sky"));
  RenderSettings rs;
  rs.width = 32, rs.height = 32, rs.spp = 4, rs.jitter = false;
  const Camera pinhole{{0, 0, 0}, {0, 0, -1}, 40};
  Camera focused = pinhole, unfocused = pinhole;
  focused.aperture_radius = unfocused.aperture_radius = 0.3f;
  focused.focus_distance = 5;
  unfocused.focus_distance = 2;
  const Frame a = r.render(pinhole, rs), b = r.render(focused, rs), c = r.render(unfocused, rs);
  double diff_focused = 0, diff_unfocused = 0;
  for (size_t i = 0; i < a[Aov::albedo].pixels.size(); ++i) {
    diff_focused = std::max(diff_focused,
                            double(std::fabs(a[Aov::albedo].pixels[i] - b[Aov::albedo].pixels[i])));
    diff_unfocused = std::max(
        diff_unfocused, double(std::fabs(a[Aov::albedo].pixels[i] - c[Aov::albedo].pixels[i])));
  }
  EXPECT_LT(diff_focused, 1e-3);
  EXPECT_GT(diff_unfocused, 0.1);
}

TEST(Aovs, ExactOnAPlane) {
  const Material mat{.name = "m", .base_color = {0.3f, 0.6f, 0.9f}, .roughness = 0.4f};
  SceneRenderer r(plane_scene(-5, mat), Environment::parse("sky"));
  RenderSettings rs;
  rs.width = 40, rs.height = 30, rs.frame = 3;
  const Camera cam{{0, 0, 0}, {0, 0, -1}, 60};
  const Frame f = r.render(cam, rs);
  for (int y = 0; y < rs.height; ++y)
    for (int x = 0; x < rs.width; ++x) {
      ASSERT_NEAR(f[Aov::depth].at(x, y)[0], 5.0f, 1e-4f);
      ASSERT_NEAR(f[Aov::normal].at(x, y)[2], 1.0f, 1e-6f);
      for (int c = 0; c < 3; ++c) ASSERT_NEAR(f[Aov::albedo].at(x, y)[c], mat.base_color[c], 1e-6f);
      ASSERT_NEAR(f[Aov::roughness].at(x, y)[0], 0.4f, 1e-6f);
      ASSERT_EQ(f[Aov::motion].at(x, y)[0], 0.0f);
      ASSERT_EQ(f[Aov::spp].at(x, y)[0], 1.0f);
      ASSERT_EQ(f[Aov::variance].at(x, y)[0], 0.0f);
    }
  // Frame 3's jitter is the Halton (2, 3) point of index 4.
  EXPECT_FLOAT_EQ(f.jitter_x, 0.125f);
  EXPECT_NEAR(f.jitter_y, 4.0f / 9.0f, 1e-6f);
}

// Each pixel's own camera ray (the renderer generates them in 4 x 4 blocks of a tile): its
// depth and normal against the analytic sphere, also where tiles and blocks are partial.
TEST(Aovs, DepthAndNormalOnASphere) {
  const Vec3 c{0.3f, -0.2f, -5};
  const float radius = 1.5f;
  Scene s;
  s.source = "test:sphere";
  s.materials = {Material{.name = "m", .base_color = {0.5f, 0.5f, 0.5f}}};
  s.meshes.push_back(uv_sphere(c, radius, 256, 512, true));
  SceneRenderer r(std::move(s), Environment::parse("sky"));
  for (const auto& [w, h] : {std::pair{64, 64}, std::pair{45, 39}}) {
    RenderSettings rs;
    rs.width = w, rs.height = h, rs.frame = 7;
    const Camera cam{{0, 0, 0}, {0, 0, -1}, 40};
    const Frame f = r.render(cam, rs);
    const Pinhole ph(cam, rs.width, rs.height);
    int checked = 0;
    for (int y = 0; y < rs.height; ++y)
      for (int x = 0; x < rs.width; ++x) {
        const Vec3 d = ph.dir(x + f.jitter_x, y + f.jitter_y);
        const Vec3 oc = sub(ph.eye, c);
        const float b = dot3(oc, d), disc = b * b - (dot3(oc, oc) - radius * radius);
        const float depth = f[Aov::depth].at(x, y)[0];
        if (disc < 0.05f) {  // misses and silhouette pixels (tessellation) are left out
          if (disc < -0.05f) {
            EXPECT_EQ(depth, 0.0f);
          }
          continue;
        }
        const float t = -b - std::sqrt(disc);
        const Vec3 p = add(ph.eye, mul(d, t));
        const Vec3 n = unit(sub(p, c));
        EXPECT_NEAR(depth, t * dot3(d, ph.f), 2e-3f * t) << x << "," << y;
        const float* nn = f[Aov::normal].at(x, y);
        EXPECT_GT(nn[0] * n.x + nn[1] * n.y + nn[2] * n.z, 0.9999f) << x << "," << y;
        ++checked;
      }
    EXPECT_GT(checked, w * h / 10) << w << "x" << h;
  }
}

TEST(MotionVectors, MovingCameraReprojectsExactly) {
  SceneRenderer r(plane_scene(-5, Material{.name = "m"}), Environment::parse("sky"));
  RenderSettings rs;
  rs.width = 48, rs.height = 32, rs.jitter = false;
  const Camera prev{{0, 0, 0}, {0.05f, 0.02f, -1}, 60};
  const Camera cur{{0.3f, 0.1f, 0.2f}, {0.2f, 0.15f, -1}, 55};
  const Frame f = r.render(cur, rs, prev);
  const Pinhole pc(cur, rs.width, rs.height), pp(prev, rs.width, rs.height);
  for (int y = 0; y < rs.height; ++y)
    for (int x = 0; x < rs.width; ++x) {
      const Vec3 d = pc.dir(x + 0.5f, y + 0.5f);
      const float t = (-5 - pc.eye.z) / d.z;
      const Vec3 p = add(pc.eye, mul(d, t));
      float gx, gy;
      pp.project(p, gx, gy);
      EXPECT_NEAR(f[Aov::motion].at(x, y)[0], gx - (x + 0.5f), 2e-3f) << x << "," << y;
      EXPECT_NEAR(f[Aov::motion].at(x, y)[1], gy - (y + 0.5f), 2e-3f) << x << "," << y;
    }
}

TEST(MotionVectors, MovingInstanceReprojectsExactly) {
  InstancedScene scene;
  TriangleMesh quad;
  add_quad(quad, {-1, -1, 0}, {1, -1, 0}, {1, 1, 0}, {-1, 1, 0}, 0);
  const MeshId mesh = scene.add_mesh(quad);
  const InstanceId inst = scene.add_instance(mesh, Affine3::translation({0, 0, -4}));
  scene.commit();
  scene.set_materials({Material{.name = "m"}});
  scene.commit();
  Renderer r(scene, Environment::parse("sky"));
  const Vec3 move{0.4f, -0.25f, 0.3f};
  scene.set_transform(inst,
                      Affine3::translation({move.x, move.y, -4 + move.z}) * Affine3::rotation_y(0));
  scene.commit();  // the renderer sees the commit at its next render
  RenderSettings rs;
  rs.width = 40, rs.height = 40, rs.jitter = false;
  const Camera cam{{0, 0, 0}, {0, 0, -1}, 50};
  const Frame f = r.render(cam, rs);
  const Pinhole ph(cam, rs.width, rs.height);
  int on_quad = 0;
  for (int y = 0; y < rs.height; ++y)
    for (int x = 0; x < rs.width; ++x) {
      if (f[Aov::depth].at(x, y)[0] == 0) {
        EXPECT_EQ(f[Aov::motion].at(x, y)[0], 0.0f);
        continue;
      }
      const Vec3 d = ph.dir(x + 0.5f, y + 0.5f);
      const float z = -4 + move.z;
      const Vec3 p = mul(d, z / d.z);
      float gx, gy;
      ph.project(sub(p, move), gx, gy);  // where this point of the quad was
      EXPECT_NEAR(f[Aov::motion].at(x, y)[0], gx - (x + 0.5f), 2e-3f);
      EXPECT_NEAR(f[Aov::motion].at(x, y)[1], gy - (y + 0.5f), 2e-3f);
      ++on_quad;
    }
  EXPECT_GT(on_quad, 200);
}

TEST(Outputs, ExrAndPfmHoldEveryAov) {
  SceneRenderer r(load_scene("builtin:cornell_box"));
  RenderSettings rs;
  rs.width = 24, rs.height = 20, rs.spp = 4;
  const Frame f = r.render(*find_view(load_scene("builtin:cornell_box"), "front"), rs);
  const std::string dir =
      std::filesystem::path(test::write_temp_file("render_out_marker", "")).parent_path().string() +
      "/render_out";
  std::filesystem::create_directories(dir);
  write_frame_exr(dir + "/frame.exr", f);
  const std::vector<ImageLayer> layers = read_exr(dir + "/frame.exr");
  ASSERT_EQ(layers.size(), size_t(aov_count));
  for (int k = 0; k < aov_count; ++k) {
    const ImageLayer* found = nullptr;
    for (const ImageLayer& l : layers)
      if (l.name == aov_name(Aov(k))) found = &l;
    ASSERT_NE(found, nullptr) << aov_name(Aov(k));
    ASSERT_EQ(found->image.channels, aov_channels(Aov(k)));
    EXPECT_EQ(found->image.pixels, f.aov[k].pixels) << aov_name(Aov(k));
  }
  write_frame_pfms(dir + "/pfm", f);
  for (int k = 0; k < aov_count; ++k) {
    const FloatImage img = read_pfm(dir + "/pfm/" + aov_name(Aov(k)) + ".pfm");
    ASSERT_EQ(img.width, f.width);
    ASSERT_EQ(img.height, f.height);
    for (int y = 0; y < img.height; ++y)
      for (int x = 0; x < img.width; ++x)
        for (int c = 0; c < aov_channels(Aov(k)); ++c)
          ASSERT_EQ(img.at(x, y)[c], f.aov[k].at(x, y)[c]) << aov_name(Aov(k));
  }
}

TEST(Cameras, OrbitTurnsTheEyeAboutTheTargetsVerticalAxis) {
  Camera start;
  start.eye = {3, 2, 0};
  start.target = {1, 0.5f, 0};
  const CameraPath p = CameraPath::orbit(start, 90.0, 2.0);
  EXPECT_EQ(p.start(), 0.0);
  EXPECT_EQ(p.end(), 2.0);
  for (double t : {0.0, 0.3, 0.77, 1.0, 1.5, 2.0}) {
    const Camera c = p.at(t);
    const float dx = c.eye.x - 1, dz = c.eye.z;
    EXPECT_NEAR(std::sqrt(dx * dx + dz * dz), 2.0f, 2e-3f)
        << t;  // on the circle (Catmull-Rom through keys 15 deg apart)
    EXPECT_NEAR(c.eye.y, 2.0f, 1e-5f) << t;
    EXPECT_NEAR(c.target.x, 1.0f, 1e-6f);
  }
  const Camera end = p.at(2.0);  // +90 degrees: (1,0,0) arm -> (0,0,-1)
  EXPECT_NEAR(end.eye.x, 1.0f, 1e-5f);
  EXPECT_NEAR(end.eye.z, -2.0f, 1e-5f);
  EXPECT_THROW(CameraPath::orbit(start, std::nan(""), 1.0), Error);
  EXPECT_THROW(CameraPath::orbit(start, 90, 0.0), Error);
}

TEST(Cameras, PathPassesThroughItsKeysAndViewsLoad) {
  const std::string path = test::write_temp_file("cam.json", R"({"keyframes": [
    {"time": 0, "eye": [0, 1, 5], "target": [0, 1, 0], "vfov": 40},
    {"time": 1, "eye": [2, 1, 4], "target": [0, 1, 0], "vfov": 50},
    {"time": 3, "eye": [4, 2, 0], "target": [0, 0, 0], "vfov": 60}]})");
  const CameraPath p = CameraPath::load(path);
  for (const auto& k : p.keys) {
    const Camera c = p.at(k.time);
    EXPECT_NEAR(c.eye.x, k.camera.eye.x, 1e-5f);
    EXPECT_NEAR(c.eye.z, k.camera.eye.z, 1e-5f);
    EXPECT_NEAR(c.vfov_degrees, k.camera.vfov_degrees, 1e-5f);
  }
  EXPECT_NEAR(p.at(0.5).vfov_degrees, 45.0f, 1e-4f);
  const auto sponza = test::shared_scene("dabrovic_sponza/sponza.obj");
  Scene s;
  s.source = sponza ? *sponza : "sponza.obj";
  const auto inside = find_view(s, "inside");
  ASSERT_TRUE(inside.has_value());
  EXPECT_NEAR(inside->eye.x, 14.4499f, 1e-4f);
  EXPECT_EQ(inside->vfov_degrees, 90.0f);
  EXPECT_FALSE(find_view(s, "no_such_view").has_value());
}

template <class F>
void expect_error(F&& f, const std::string& needle) {
  try {
    f();
    ADD_FAILURE() << "no error; expected one naming '" << needle << "'";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find(needle), std::string::npos) << e.what();
  }
}

TEST(ToneMap, Srgb8IsTheDocumentedCurveForEveryValue) {
  // tonemap_srgb8 (vectorised, a table for the OETF) against the scalar curve: within one
  // code value for every pixel and exposure, odd sizes, 3 and 4 channels; NaN, negatives and
  // -inf black, +inf white.
  for (int channels : {3, 4})
    for (float stops : {0.0f, -2.5f, 3.0f}) {
      FloatImage img(37, 5, channels);  // 185 pixels: not a multiple of 4 or of the block
      uint64_t state = 7;
      for (float& v : img.pixels) {
        state = state * 6364136223846793005ull + 1442695040888963407ull;
        v = std::ldexp(float(state >> 40) / float(1 << 24), int(state >> 60) - 8);  // 2^-8..2^7
      }
      const float special[] = {NAN, -1.0f, -INFINITY, INFINITY, 0.0f, 1e30f, 1e-30f};
      for (size_t i = 0; i < std::size(special); ++i) img.pixels[i * 5] = special[i];
      const std::vector<uint8_t> out = tonemap_srgb8(img, stops);
      ASSERT_EQ(out.size(), size_t(37 * 5 * 3));
      for (size_t p = 0; p < size_t(37 * 5); ++p)
        for (size_t c = 0; c < 3; ++c) {
          const float x = img.pixels[p * size_t(channels) + c];
          const double want = 255.0 * tonemap_aces_srgb(x * std::exp2(stops));
          EXPECT_NEAR(out[3 * p + c], want, 1.0) << "value " << x << " stops " << stops;
          if (!(x > 0)) {
            EXPECT_EQ(out[3 * p + c], 0) << x;
          }
          if (x == INFINITY) {
            EXPECT_EQ(out[3 * p + c], 255);
          }
        }
    }
}

TEST(BadInput, ClearErrors) {
  expect_error([] { Environment::parse("constant:1,x,2"); }, "constant:R,G,B");
  expect_error([] { Environment::parse("constant:1,-1,2"); }, ">= 0");
  expect_error([] { Environment::parse("/no/such/env.hdr"); }, "/no/such/env.hdr");
  const std::string truncated = test::write_temp_file("trunc.pfm", "PF\n4 4\n-1.0\n0123");
  expect_error([&] { read_pfm(truncated); }, "trunc.pfm");
  const std::string not_pfm = test::write_temp_file("bad.pfm", "P6\n4 4\n255\n");
  expect_error([&] { read_pfm(not_pfm); }, "not a PFM");
  const std::string garbage =
      test::write_temp_file("garbage.exr", "this is not an EXR file at all");
  expect_error([&] { read_exr(garbage); }, "garbage.exr");
  FloatImage nan_env(4, 2, 3);
  nan_env.pixels[5] = NAN;
  const std::string nan_path = test::write_temp_file("nan_env.pfm", "");
  write_pfm(nan_path, nan_env);
  expect_error([&] { Environment::parse(nan_path); }, "NaN");
  const std::string bad_json =
      test::write_temp_file("bad.views.json", "{\"views\": {\"a\": {\"eye\": [1, 2]}}}");
  expect_error([&] { load_views(bad_json); }, "bad.views.json");
  const std::string bad_path = test::write_temp_file(
      "bad_path.json",
      R"({"keyframes": [{"time": 1, "eye": [0,0,1], "target": [0,0,0]}, {"time": 0, "eye": [0,0,2], "target": [0,0,0]}]})");
  expect_error([&] { CameraPath::load(bad_path); }, "increasing");
  SceneRenderer r(load_scene("builtin:cornell_box"));
  RenderSettings rs;
  rs.spp = 0;
  expect_error([&] { r.render(Camera{{0, 0, 0}, {0, 0, 1}, 45}, rs); }, "spp");
  rs = RenderSettings{};
  rs.indirect_rate = 0.3f;
  expect_error([&] { r.render(Camera{{0, 0, 0}, {0, 0, 1}, 45}, rs); }, "indirect rate");
  rs = RenderSettings{};
  rs.width = 0;
  expect_error([&] { r.render(Camera{{0, 0, 0}, {0, 0, 1}, 45}, rs); }, "resolution");
  expect_error([&] { r.render(Camera{{1, 1, 1}, {1, 1, 1}, 45}, RenderSettings{}); }, "coincide");
  Scene s = plane_scene(-1, Material{.name = "m"});
  s.meshes[0].material_ids[1] = 7;
  expect_error([&] { SceneRenderer bad(std::move(s)); }, "material 7");
  Scene empty;
  empty.source = "test:empty";
  expect_error([&] { SceneRenderer bad(std::move(empty)); }, "test:empty: no valid triangle");
  Scene nan_mat = plane_scene(-1, Material{.name = "glow", .emission = {NAN, 0, 0}});
  expect_error([&] { SceneRenderer bad(std::move(nan_mat)); }, "glow");
}

TEST(BadInput, CorruptTextureIsAWarningNamingTheFile) {
  test::write_temp_file("corrupt_tex.png", "\x89PNG\r\n\x1a\n not really a png");
  test::write_temp_file("corrupt_tex.mtl", "newmtl m\nKd 1 1 1\nmap_Kd corrupt_tex.png\n");
  const std::string obj =
      test::write_temp_file("corrupt_tex.obj",
                            "mtllib corrupt_tex.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt "
                            "0 1\nusemtl m\nf 1/1 2/2 3/3\n");
  const Scene s = load_scene(obj);
  ASSERT_EQ(s.warnings.size(), 1u);
  EXPECT_NE(s.warnings[0].find("corrupt_tex.png"), std::string::npos) << s.warnings[0];
  SceneRenderer r(s, Environment::parse("sky"));
  RenderSettings rs;
  rs.width = 8, rs.height = 8;
  EXPECT_NO_THROW(r.render(Camera{{0.2f, 0.2f, 2}, {0.2f, 0.2f, 0}, 30}, rs));
}

TEST(Render, NanGeometryIsSkippedNotFatal) {
  Scene s = plane_scene(-5, Material{.name = "m"});
  TriangleMesh bad;
  add_quad(bad, {NAN, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0}, 0);
  s.meshes.push_back(bad);
  SceneRenderer r(std::move(s), Environment::parse("sky"));
  RenderSettings rs;
  rs.width = 16, rs.height = 16;
  const Frame f = r.render(Camera{{0, 0, 0}, {0, 0, -1}, 60}, rs);
  for (float v : f[Aov::color].pixels) ASSERT_TRUE(std::isfinite(v));
}

}  // namespace
}  // namespace kestrel
