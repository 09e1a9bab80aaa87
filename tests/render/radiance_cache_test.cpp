// The radiance cache against oracles: its cells' arithmetic (exact means, the history cap,
// eviction, keys by cell and face), the closed emitting box whose radiance is known in
// closed form (every cell of it has the same outgoing radiance, so the cache may blur but
// must not bias), full paths where the cache must not apply (mirrors: the same bits), and
// the same bits for any thread count and for a frame index that starts afresh.
#include <gtest/gtest.h>

#include <cmath>

#include "kestrel/kestrel.h"
#include "render/radiance_cache.h"
#include "support/oracles.h"

namespace kestrel {
namespace {

using render::CacheRecord;
using render::RadianceCache;

RadianceCache cache_at_origin() {
  RadianceCache c;
  c.set_view({0, 0, 0}, 0.01f);
  return c;
}

TEST(RadianceCacheCells, SizeIsThePowerOfTwoAboveEightPixels) {
  const RadianceCache c = cache_at_origin();
  for (float d : {0.3f, 1.0f, 7.0f, 100.0f, 3e4f}) {
    const float want = d * 0.01f * RadianceCache::cell_pixels;
    const float got = c.cell({0, 0, d}, {0, 0, 1}).size;
    int e = 0;
    EXPECT_EQ(std::frexp(got, &e), 0.5f) << d;  // a power of two
    EXPECT_GE(got, want) << d;
    EXPECT_LE(got, 2 * want) << d;
  }
}

TEST(RadianceCacheCells, KeysFollowCellsAndFaces) {
  const RadianceCache c = cache_at_origin();
  const Vec3 up{0, 1, 0};
  const Vec3 p{10.1f, 0.3f, 20.2f};  // distance ~22.6: cells of 2
  const float cell = c.cell(p, {0, 0, 1}).size;
  ASSERT_EQ(cell, 2.0f);
  EXPECT_EQ(c.cell(p, up).key,
            c.cell({10.9f, 1.9f, 21.9f}, {0.1f, 0.9f, 0.2f}).key);     // same cell, face
  EXPECT_NE(c.cell(p, up).key, c.cell(p, {0, -1, 0}).key);             // the other face
  EXPECT_NE(c.cell(p, up).key, c.cell({12.1f, 0.3f, 20.2f}, up).key);  // the next cell
  EXPECT_NE(c.cell(p, up).key, 0u);
  // Huge and tiny coordinates still give keys (clamped cells), never the empty one.
  EXPECT_NE(c.cell({3e38f, -3e38f, 1e-30f}, up).key, 0u);
}

TEST(RadianceCacheCells, MeansAreExactAndHistoryIsCapped) {
  RadianceCache c = cache_at_origin();
  const uint64_t k = c.cell({1, 2, 3}, {0, 0, 1}).key;
  Vec3 out;
  std::vector<CacheRecord> rs;
  for (int i = 0; i < 3; ++i) rs.push_back({k, {float(i), 1, 2}});
  c.add(rs);
  c.end_pass();
  EXPECT_FALSE(c.lookup(k, out)) << "three samples are below min_samples";
  rs = {{k, {7, 1, 2}}, {k, {7, 1, 2}}};
  c.add(rs);
  c.end_pass();
  ASSERT_TRUE(c.lookup(k, out));
  const float aged = 3 * std::exp2(-1.0f / RadianceCache::half_life);  // one pass later
  EXPECT_FLOAT_EQ(out.x, (aged * 1 + 7 + 7) / (aged + 2));
  EXPECT_FLOAT_EQ(out.y, 1);
  // max_samples of a new value push the old ones out entirely.
  rs.assign(size_t(RadianceCache::max_samples), {k, {3, 3, 3}});
  c.add(rs);
  c.end_pass();
  ASSERT_TRUE(c.lookup(k, out));
  EXPECT_FLOAT_EQ(out.x, 3);
  EXPECT_FLOAT_EQ(out.z, 3);
  // A cell without samples for max_age passes is dropped; one that keeps getting them stays.
  const uint64_t k2 = c.cell({-5, 2, 3}, {0, 0, 1}).key;
  for (uint32_t p = 0; p <= RadianceCache::max_age + 16; ++p) {
    rs.assign(4, {k2, {1, 1, 1}});
    c.add(rs);
    c.end_pass();
  }
  EXPECT_FALSE(c.lookup(k, out));
  EXPECT_TRUE(c.lookup(k2, out));
  EXPECT_EQ(c.cells(), 1u);
}

TEST(RadianceCacheCells, AFullTableOfYoungCellsKeepsTheMostRecentAndMakesRoom) {
  // Four passes of 16 000 new cells each (4 samples apiece, so each answers): after the
  // fourth the table holds more than evict_at cells, all far younger than max_age. The
  // eviction keeps the most recent passes' cells up to keep_at (three passes: 48 000) and
  // drops the oldest pass's, so the table has room again instead of evicting nothing.
  RadianceCache c = cache_at_origin();
  constexpr uint64_t per_pass = 16000;
  static_assert(4 * per_pass >= RadianceCache::evict_at);
  static_assert(3 * per_pass <= RadianceCache::keep_at && 4 * per_pass > RadianceCache::keep_at);
  const auto key = [](uint64_t i) { return 2 * i + 1; };
  std::vector<CacheRecord> rs;
  for (uint64_t pass = 0; pass < 4; ++pass) {
    rs.clear();
    for (uint64_t i = pass * per_pass; i < (pass + 1) * per_pass; ++i)
      for (int s = 0; s < 4; ++s) rs.push_back({key(i), {float(pass), 1, 1}});
    c.add(rs);
    c.end_pass();
    if (pass < 3) {
      EXPECT_EQ(c.cells(), (pass + 1) * per_pass) << pass;
    }
  }
  EXPECT_EQ(c.cells(), 3 * per_pass);
  Vec3 out;
  EXPECT_FALSE(c.lookup(key(0), out)) << "the oldest pass's cells go";
  EXPECT_FALSE(c.lookup(key(per_pass - 1), out));
  for (uint64_t i : {per_pass, 2 * per_pass + 7, 4 * per_pass - 1}) {
    ASSERT_TRUE(c.lookup(key(i), out)) << i;
    EXPECT_EQ(out.x, float(i / per_pass)) << i;
  }
  // A new cell is taken in and answers.
  rs.assign(4, {key(5 * per_pass), {9, 9, 9}});
  c.add(rs);
  c.end_pass();
  ASSERT_TRUE(c.lookup(key(5 * per_pass), out));
  EXPECT_EQ(out.x, 9);
}

TEST(RadianceCacheCells, ChangedLightingReachesAFullCellWithinEightHalfLives) {
  // A cell full of history (max_samples of 1) then one sample of 3 per pass: the history
  // halves every half_life passes, so the mean follows although few samples arrive.
  RadianceCache c = cache_at_origin();
  const uint64_t k = c.cell({1, 2, 3}, {0, 0, 1}).key;
  std::vector<CacheRecord> rs(size_t(RadianceCache::max_samples), {k, {1, 1, 1}});
  c.add(rs);
  c.end_pass();
  Vec3 out;
  for (uint32_t p = 0; p < 8 * RadianceCache::half_life; ++p) {
    rs.assign(1, {k, {3, 3, 3}});
    c.add(rs);
    c.end_pass();
    if (p == RadianceCache::half_life - 1) {
      ASSERT_TRUE(c.lookup(k, out));
      EXPECT_GT(out.x, 1.15f) << "after one half-life";
      EXPECT_LT(out.x, 2.0f) << "after one half-life";
    }
  }
  ASSERT_TRUE(c.lookup(k, out));
  EXPECT_GT(out.x, 2.9f);
}

// Every wall emits 1 and reflects 0.5 (Lambertian): the radiance of a path of at most D
// vertices is sum_{k<D} 0.5^k everywhere inside.
struct EmittingBox {
  Asset asset;
  EmittingBox() : asset(Asset::from_scene(make())) {}
  static Scene make() {
    Scene s;
    s.source = "test:cache_box";
    s.materials = {
        Material{.name = "wall", .base_color = {0.5f, 0.5f, 0.5f}, .emission = {1, 1, 1}}};
    s.meshes.push_back(test::closed_box({-1, -1, -1}, {1, 1, 1}).meshes[0]);
    s.meshes[0].material_ids.assign(s.meshes[0].triangle_count(), 0);
    return s;
  }
};

double mean_of(const FloatImage& img) {
  double sum = 0;
  for (float v : img.pixels) sum += v;
  return sum / double(img.pixels.size());
}

TEST(RadianceCacheRender, ClosedEmittingBoxKeepsItsRadianceWithFewerRays) {
  EmittingBox box;
  const Camera cam{{0.2f, 0.1f, -0.3f}, {0.5f, 0.3f, 0.8f}, 80};
  const double want = 2.0 * (1.0 - std::pow(0.5, 6));  // max_depth 6
  RenderSettings rs;
  rs.width = 48, rs.height = 48, rs.max_depth = 6;
  uint64_t full_rays = 0, cached_rays = 0;
  double full_sum = 0, cached_sum = 0, full_sq = 0, cached_sq = 0;
  for (const bool cache : {false, true}) {
    Renderer r(box.asset.scene(), Environment::parse("none"));
    rs.radiance_cache = cache;
    const int warm = 4, frames = 40;
    for (int f = 0; f < warm + frames; ++f) {
      rs.frame = uint32_t(f);
      const Frame out = r.render(cam, rs, cam);
      if (f < warm) continue;
      const double m = mean_of(out[Aov::color]);
      double sq = 0;
      for (float v : out[Aov::color].pixels) sq += (v - want) * (v - want);
      (cache ? cached_sum : full_sum) += m / frames;
      (cache ? cached_sq : full_sq) += sq / double(out[Aov::color].pixels.size()) / frames;
      (cache ? cached_rays : full_rays) += out.stats.rays();
    }
  }
  EXPECT_NEAR(full_sum, want, 0.01 * want);
  EXPECT_NEAR(cached_sum, want, 0.01 * want) << "the cache biased a uniform box";
  EXPECT_LT(double(cached_rays), 0.75 * double(full_rays));
  EXPECT_LT(cached_sq, 0.5 * full_sq) << "the cache should remove most indirect noise";
}

TEST(RadianceCacheRender, MirrorsKeepFullPaths) {
  // A mirror box: no first surface is rough, so no path may stop at the cache.
  Scene s = EmittingBox::make();
  s.materials[0].metallic = 1, s.materials[0].roughness = 0.05f;
  s.materials[0].base_color = {0.9f, 0.9f, 0.9f};
  const Asset asset = Asset::from_scene(std::move(s));
  const Camera cam{{0.2f, 0.1f, -0.3f}, {0.5f, 0.3f, 0.8f}, 80};
  Frame out[2];
  for (int cache = 0; cache < 2; ++cache) {
    Renderer r(asset.scene(), Environment::parse("none"));
    RenderSettings rs;
    rs.width = 32, rs.height = 32, rs.max_depth = 6, rs.radiance_cache = cache == 1;
    for (uint32_t f = 0; f < 3; ++f) rs.frame = f, out[cache] = r.render(cam, rs, cam);
  }
  EXPECT_EQ(out[0][Aov::color].pixels, out[1][Aov::color].pixels);
}

// The Cornell box (its light, coloured walls, boxes), three frames of a moving camera.
std::vector<float> cornell_frames(int threads, uint32_t first, uint32_t last) {
  const Asset asset = Asset::load("builtin:cornell_box");
  Renderer r(asset.scene());
  Camera cam = *find_view(asset, "framing");
  RenderSettings rs;
  rs.width = 64, rs.height = 48, rs.max_depth = 5, rs.radiance_cache = true;
  rs.threads = threads;
  std::vector<float> all;
  for (uint32_t f = first; f <= last; ++f) {
    const Camera prev = cam;
    cam.eye.x += 0.01f;
    rs.frame = f;
    const Frame out = r.render(cam, rs, prev);
    all.insert(all.end(), out[Aov::color].pixels.begin(), out[Aov::color].pixels.end());
  }
  return all;
}

TEST(RadianceCacheRender, SameBitsForAnyThreadCount) {
  EXPECT_EQ(cornell_frames(1, 0, 4), cornell_frames(2, 0, 4));
}

TEST(RadianceCacheRender, AFrameOutOfSequenceStartsAfresh) {
  // Frames 0..4 then frame 9 on one renderer; frame 9 alone on another: the cache of frames
  // 0..4 must not reach frame 9 (the camera has moved once in both).
  const std::vector<float> fresh = cornell_frames(2, 9, 9);
  const Asset asset = Asset::load("builtin:cornell_box");
  Renderer r(asset.scene());
  Camera cam = *find_view(asset, "framing");
  RenderSettings rs;
  rs.width = 64, rs.height = 48, rs.max_depth = 5, rs.radiance_cache = true, rs.threads = 2;
  for (uint32_t f = 0; f < 5; ++f) rs.frame = f, r.render(cam, rs, cam);
  const Camera prev = cam;
  cam.eye.x += 0.01f;
  rs.frame = 9;
  EXPECT_EQ(r.render(cam, rs, prev)[Aov::color].pixels, fresh);
  // Frame 10 does read frame 9's cache: not what a fresh renderer shows.
  Renderer fresh10(asset.scene());
  rs.frame = 10;
  EXPECT_NE(r.render(cam, rs, cam)[Aov::color].pixels,
            fresh10.render(cam, rs, cam)[Aov::color].pixels);
}

}  // namespace
}  // namespace kestrel
