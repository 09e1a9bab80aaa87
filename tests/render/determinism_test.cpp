// The renderer's determinism: the same bits for one and two threads, for any wave of tiles
// (NEE, ReSTIR, the radiance cache), for a render into a kept frame and for tiles rendered
// apart; and the render's own account of where its time went.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>

#include "kestrel/instances.h"
#include "kestrel/isa.h"
#include "kestrel/render.h"
#include "render/testing.h"
#include "support/oracles.h"
#include "support/scene_renderer.h"

namespace kestrel {
namespace {

using test::SceneRenderer;

TEST(Determinism, SameBitsForOneAndTwoThreads) {
  SceneRenderer r(load_scene("builtin:cornell_box"));
  RenderSettings rs;
  rs.width = 72, rs.height = 56, rs.spp = 3, rs.seed = 42;
  const Camera cam = *find_view(load_scene("builtin:cornell_box"), "front");
  rs.threads = 1;
  const Frame a = r.render(cam, rs);
  rs.threads = 2;
  const Frame b = r.render(cam, rs);
  for (int k = 0; k < aov_count; ++k)
    EXPECT_EQ(a.aov[k].pixels, b.aov[k].pixels) << aov_name(Aov(k));
  rs.seed = 43;
  const Frame c = r.render(cam, rs);
  EXPECT_NE(a[Aov::color].pixels, c[Aov::color].pixels);
}

// The path tracer traces a wave of tiles together: each bounce of the wave's paths is one
// batch, here large enough for the batch API's ray streams (checked through the ray capture).
// Waves of one tile, of five tiles and the default give the same bits on one and two threads,
// with NEE, ReSTIR and the radiance cache, over frames that reuse ReSTIR's and the cache's
// history: a tile reading another's hits or results would show.
TEST(Determinism, SameBitsForAnyWaveOfTiles) {
  SceneRenderer plain(load_scene("builtin:cornell_box"));
  const Camera cam = *find_view(load_scene("builtin:cornell_box"), "front");
  RenderSettings rs;
  rs.width = 400, rs.height = 300, rs.max_depth = 4, rs.seed = 7;
  RayCapture capture;
  RendererTesting::set_capture(plain, &capture);
  plain.render(cam, rs);
  RendererTesting::set_capture(plain, nullptr);
  ASSERT_FALSE(capture.bounce_batches.empty());
  EXPECT_GE(*std::max_element(capture.bounce_batches.begin(), capture.bounce_batches.end()),
            size_t(1) << 16);
  auto frames = [&](size_t wave, int threads) {
    SceneRenderer r(load_scene("builtin:cornell_box"));
    if (wave > 0) RendererTesting::set_wave_tiles(r, wave);
    std::vector<std::vector<float>> out;
    RenderSettings s = rs;
    s.threads = threads;
    for (uint32_t f = 0; f < 4; ++f) {
      s.frame = f;
      s.direct = f < 2 ? DirectLighting::restir : DirectLighting::nee;
      s.radiance_cache = f >= 1;
      s.spp = f == 3 ? 2 : 1;
      const Frame fr = r.render(cam, s, cam);
      for (int k = 0; k < aov_count; ++k) out.push_back(fr.aov[k].pixels);
    }
    return out;
  };
  const auto reference = frames(1, 1);
  EXPECT_EQ(frames(0, 1), reference);
  EXPECT_EQ(frames(0, 2), reference);
  EXPECT_EQ(frames(5, 2), reference);
}

// The shading takes hits' surfaces (and first hits' base texels) from SIMD rows
// (render/surface_rows.h) where a group's hits lie on an identity-transformed mesh, else from
// surface_at: every AOV must be the same bits
// either way, on every ISA this CPU runs. The scene mixes what the rows must get right: a
// bumpy textured mesh whose vertex normals are sometimes zero, infinite, NaN or turned away
// from the surface, texture coordinates beyond [0, 1], a mesh without normals or texture
// coordinates, and both meshes again under transforms (surface_at's lanes in the same groups).
TEST(Determinism, SurfaceRowsGiveTheSurfacesBitForBit) {
  InstancedScene scene;
  TriangleMesh bumpy;
  constexpr int n = 24;
  for (int j = 0; j <= n; ++j)
    for (int i = 0; i <= n; ++i) {
      const float x = -2 + 4.0f * float(i) / n, y = -2 + 4.0f * float(j) / n;
      const float z = 0.3f * std::sin(2.1f * x) * std::cos(1.7f * y);
      bumpy.positions.push_back({x, y, z});
      Vec3 nrm{-0.63f * std::cos(2.1f * x) * std::cos(1.7f * y),
               0.51f * std::sin(2.1f * x) * std::sin(1.7f * y), 1};
      // Some vertex normals the shading must not trust: zero, infinite, NaN, turned away
      // from the surface, grazing.
      const Vec3 odd[5] = {
          {0, 0, 0}, {INFINITY, 0, 1}, {NAN, 0, 1}, {-nrm.x, -nrm.y, -1}, {nrm.x, 3.0f, 0.05f}};
      const int which = (i * 7 + j * 3) % 23;
      if (which < 5) nrm = odd[which];
      bumpy.normals.push_back(nrm);
      bumpy.uvs.push_back({1.7f * x - 0.4f, 2.3f * y + 0.6f});
    }
  for (int j = 0; j < n; ++j)
    for (int i = 0; i < n; ++i) {
      const uint32_t a = uint32_t(j * (n + 1) + i), b = a + 1, c = a + uint32_t(n) + 1, d = c + 1;
      bumpy.indices.insert(bumpy.indices.end(), {a, b, d, a, d, c});
      bumpy.material_ids.insert(bumpy.material_ids.end(), {uint32_t((i + j) % 2), 0});
    }
  TriangleMesh plain;  // no normals, no texture coordinates
  uint64_t seed = 12345;
  auto uniform = [&] {
    seed = seed * 6364136223846793005ull + 1442695040888963407ull;
    return float(seed >> 40) / float(1 << 24);
  };
  for (uint32_t t = 0; t < 300; ++t) {
    const Vec3 c{uniform() * 4 - 2, uniform() * 4 - 2, uniform() * 0.8f + 0.2f};
    for (int v = 0; v < 3; ++v)
      plain.positions.push_back({c.x + uniform() * 0.6f - 0.3f, c.y + uniform() * 0.6f - 0.3f,
                                 c.z + uniform() * 0.6f - 0.3f});
    plain.indices.insert(plain.indices.end(), {3 * t, 3 * t + 1, 3 * t + 2});
    plain.material_ids.push_back(1);
  }
  const MeshId mb = scene.add_mesh(bumpy), mp = scene.add_mesh(plain);
  scene.add_instance(mb, Affine3::translation({0, 0, 0}));
  scene.add_instance(mp, Affine3::translation({0, 0, 0}));
  scene.add_instance(mb, Affine3::translation({0.7f, -0.4f, 0.9f}) * Affine3::rotation_y(0.4f));
  scene.add_instance(mp, Affine3::translation({-1.1f, 0.8f, 0.5f}) * Affine3::rotation_y(-0.3f));
  Texture checker{"checker", 8, 8, {}};
  for (int k = 0; k < 64; ++k)
    for (int c = 0; c < 4; ++c) checker.rgba.push_back(uint8_t((k * 37 + c * 91) % 256));
  Material textured{.name = "textured"};
  textured.base_color_texture = 0;
  textured.roughness = 0.4f, textured.metallic = 0.3f;
  Material rough{.name = "rough"};
  scene.commit();
  scene.set_materials({textured, rough}, {checker});
  scene.commit();
  const Camera cam{{0.3f, -3.6f, 3.2f}, {0.0f, 0.2f, 0.0f}, 55};  // eye, target, fov
  RenderSettings rs;
  rs.width = 96, rs.height = 72, rs.max_depth = 4, rs.seed = 3;
  auto frames = [&](bool rows) {
    Environment env = Environment::parse("sky");
    env.sun = Sun{};
    env.sun->direction = normalize(Vec3{0.3f, 0.6f, 0.7f});
    Renderer r(scene, env);
    RendererTesting::set_surface_rows(r, rows);
    std::vector<std::vector<float>> out;
    RenderSettings s = rs;
    for (uint32_t f = 0; f < 3; ++f) {
      s.frame = f;
      s.direct = f == 0 ? DirectLighting::restir : DirectLighting::nee;
      s.radiance_cache = f >= 1;
      s.spp = f == 2 ? 2 : 1;
      const Frame fr = r.render(cam, s, cam);
      for (int k = 0; k < aov_count; ++k) out.push_back(fr.aov[k].pixels);
    }
    return out;
  };
  const Isa before = default_isa();
  for (Isa isa : {Isa::sse2, Isa::avx2, Isa::avx512}) {
    if (!isa_supported(isa)) continue;
    SCOPED_TRACE(isa_name(isa));
    set_default_isa(isa);
    const auto with = frames(true), without = frames(false);
    ASSERT_EQ(with.size(), without.size());
    for (size_t k = 0; k < with.size(); ++k) {
      ASSERT_EQ(with[k].size(), without[k].size());
      EXPECT_EQ(std::memcmp(with[k].data(), without[k].data(), with[k].size() * sizeof(float)), 0)
          << "frame " << k / aov_count << ", " << aov_name(Aov(k % aov_count));
    }
  }
  set_default_isa(before);
}

TEST(Determinism, RenderIntoAKeptFrameIsAFreshRender) {
  // What the frame loop relies on: a Frame kept from frame to frame (last holding another
  // size, seed and sample count) gets the fresh render's bits and stats, in the same storage
  // when the size repeats.
  SceneRenderer r(load_scene("builtin:cornell_box"));
  const Camera cam = *find_view(load_scene("builtin:cornell_box"), "front");
  RenderSettings big;
  big.width = 80, big.height = 60, big.spp = 2, big.seed = 5;
  RenderSettings rs;
  rs.width = 72, rs.height = 56, rs.spp = 3, rs.seed = 42;
  Frame kept;
  r.render(cam, big, std::nullopt, kept);
  r.render(cam, rs, std::nullopt, kept);
  const Frame fresh = r.render(cam, rs);
  ASSERT_EQ(kept.width, 72);
  ASSERT_EQ(kept.height, 56);
  for (int k = 0; k < aov_count; ++k) {
    EXPECT_EQ(kept.aov[k].pixels, fresh.aov[k].pixels) << aov_name(Aov(k));
    EXPECT_EQ(kept.aov[k].channels, fresh.aov[k].channels) << aov_name(Aov(k));
  }
  EXPECT_EQ(kept.stats.camera_rays, fresh.stats.camera_rays);
  EXPECT_EQ(kept.stats.bounce_rays, fresh.stats.bounce_rays);
  const float* storage = kept[Aov::color].pixels.data();
  r.render(cam, rs, std::nullopt, kept);
  EXPECT_EQ(kept[Aov::color].pixels.data(), storage);
  EXPECT_EQ(kept[Aov::color].pixels, fresh[Aov::color].pixels);
}

class TilesApart : public ::testing::TestWithParam<int> {};

TEST_P(TilesApart, EqualOneRender) {
  // What distributed rendering relies on: any split of the tiles, in any order, over several
  // calls gives render()'s bits for every pixel (72x56: edge tiles of 8 and 24 pixels). At
  // 1 spp render() writes the samples straight into the frame, render_tiles() sums them:
  // the same means.
  SceneRenderer r(load_scene("builtin:cornell_box"));
  RenderSettings rs;
  rs.width = 72, rs.height = 56, rs.spp = GetParam(), rs.seed = 7;
  const Camera cam = *find_view(load_scene("builtin:cornell_box"), "front");
  Camera prev = cam;
  prev.eye.x += 0.01f;
  const Frame whole = r.render(cam, rs, prev);
  const size_t tiles = render_tile_count(rs.width, rs.height);
  ASSERT_EQ(tiles, 6u);
  Frame parts;
  const std::vector<uint32_t> first = {5, 0, 3}, second = {1, 4}, third = {2};
  for (const auto* list : {&first, &second, &third}) r.render_tiles(cam, rs, *list, parts, prev);
  for (int k = 0; k < aov_count; ++k)
    EXPECT_EQ(whole.aov[k].pixels, parts.aov[k].pixels) << aov_name(Aov(k));
  EXPECT_EQ(parts.stats.camera_rays, whole.stats.camera_rays);
  // A tile rendered again (another frame's settings in between) is the same again.
  RenderSettings other = rs;
  other.seed = 8;
  Frame scratch;
  r.render_tiles(cam, other, first, scratch, prev);
  r.render_tiles(cam, rs, first, scratch, prev);
  for (int k = 0; k < aov_count; ++k) {
    const FloatImage& a = whole.aov[k];
    const FloatImage& b = scratch.aov[k];
    for (int y = 0; y < 32; ++y)
      for (int x = 0; x < 32; ++x)
        for (int c = 0; c < a.channels; ++c)
          ASSERT_EQ(a.at(x, y)[c], b.at(x, y)[c]) << aov_name(Aov(k));
  }
  EXPECT_THROW(r.render_tiles(cam, rs, std::vector<uint32_t>{6}, parts), Error);
  rs.time_limit_s = 1;
  EXPECT_THROW(r.render_tiles(cam, rs, first, parts), Error);
}

INSTANTIATE_TEST_SUITE_P(Spp, TilesApart, ::testing::Values(3, 1));

// RenderStats::steps splits the render's wall time by step of the wavefront: each step that
// ran took time, the steps add up to most of the render (the rest: each pass's setup and the
// radiance cache's merge) and never to more, and a render without bounces spends nothing on
// them.
TEST(RenderStats, StepsAccountForTheRender) {
  SceneRenderer r(load_scene("builtin:cornell_box"));
  const Camera cam = *find_view(load_scene("builtin:cornell_box"), "front");
  RenderSettings rs;
  rs.width = 320, rs.height = 240, rs.spp = 2, rs.max_depth = 4;
  const RenderStats s = r.render(cam, rs).stats;
  const RenderStats::Steps& t = s.steps;
  double sum = 0;
  for (const auto& [name, m] : RenderStats::Steps::fields()) {
    EXPECT_GE(t.*m, 0.0) << name;
    sum += t.*m;
  }
  EXPECT_GT(t.trace_camera, 0.0);
  EXPECT_GT(t.shade_first, 0.0);
  EXPECT_GT(s.bounce_rays, 0u);
  EXPECT_GT(t.trace_bounces, 0.0);
  EXPECT_GT(t.shade_bounces, 0.0);
  EXPECT_LE(sum, s.ms + 1e-6);
  EXPECT_GE(sum, 0.5 * s.ms);
  rs.max_depth = 1;  // camera rays and their hits' light only
  const RenderStats direct = r.render(cam, rs).stats;
  EXPECT_EQ(direct.bounce_rays, 0u);
  EXPECT_EQ(direct.steps.shade_bounces, 0.0);
  EXPECT_GT(direct.steps.shade_first, 0.0);
}

}  // namespace
}  // namespace kestrel
