// The real-time loop: stage outputs have the right sizes and are finite, the adaptive factor
// moves towards the target frame time, the progressive reference accumulates only while the
// camera rests and converges towards a many-sample render, and bad settings are errors.
#include <gtest/gtest.h>

#include <cmath>

#include "kestrel/asset.h"
#include "kestrel/error.h"
#include "kestrel/pipeline.h"
#include "kestrel/render.h"
#include "kestrel/scene.h"

namespace kestrel {
namespace {

PipelineSettings small(int factor) {
  PipelineSettings s;
  s.width = 64, s.height = 48, s.factor = factor, s.max_depth = 3;
  return s;
}

Camera front() {
  return framing_camera(load_scene("builtin:cornell_box"));
}

TEST(Pipeline, StagesHaveTheirSizesAndFiniteValues) {
  for (int factor : {1, 2, 4}) {
    Pipeline p("builtin:cornell_box", small(factor));
    const PipelineFrame* f = nullptr;
    for (int i = 0; i < 3; ++i) f = &p.frame(front(), 0.0);
    EXPECT_EQ(f->noisy.width, 64 / factor);
    EXPECT_EQ(f->denoised.width, 64 / factor);
    EXPECT_EQ(f->upscaled.width, 64);
    EXPECT_EQ(f->upscaled.height, 48);
    EXPECT_EQ(f->rgb8.size(), size_t(64 * 48 * 3));
    EXPECT_EQ(f->index, 3u);
    EXPECT_GT(f->stats.rays(), 0u);
    EXPECT_GT(f->times.render, 0.0);
    EXPECT_GE(f->times.total, f->times.render + f->times.denoise + f->times.upscale);
    for (float v : f->upscaled.pixels) ASSERT_TRUE(std::isfinite(v) && v >= 0);
  }
}

// The one frame loop: the frame's render is Renderer::render's (same bits), its AOVs come
// with it, and a render function (distributed rendering) replaces the render; an empty frame
// (a worker process) skips the stages after it.
TEST(Pipeline, RendersAsTheRendererAndTakesARenderFunction) {
  PipelineSettings s = small(1);
  s.denoise = false;
  Pipeline p("builtin:cornell_box", s);
  const PipelineFrame& f = p.frame(front(), 0.0);
  const Asset asset = Asset::load("builtin:cornell_box");
  Renderer r(asset.scene());
  RenderSettings rs;
  rs.width = 64, rs.height = 48, rs.max_depth = 3, rs.clamp = s.clamp, rs.fixed_jitter = true;
  const Frame want = r.render(front(), rs);
  EXPECT_EQ(f.noisy.pixels, want[Aov::color].pixels);
  EXPECT_EQ(f.render[Aov::depth].pixels, want[Aov::depth].pixels);
  EXPECT_EQ(f.upscaled.pixels, want[Aov::color].pixels);
  int calls = 0;
  p.set_render_function([&](Renderer&, const Camera&, const RenderSettings& settings,
                            const std::optional<Camera>& prev) {
    ++calls;
    EXPECT_EQ(settings.frame, 1u);
    EXPECT_TRUE(prev.has_value());
    return Frame{};
  });
  const PipelineFrame& g = p.frame(front(), 0.0);
  EXPECT_EQ(calls, 1);
  EXPECT_EQ(g.render.width, 0);
  EXPECT_EQ(g.index, 2u);
}

// Lighting chosen by the scene: many lights get ReSTIR over the light tree, and the loop's
// frames are the Renderer's ReSTIR frames (history from frame to frame); few lights keep the
// settings' choice; without auto_lighting the settings rule.
TEST(Pipeline, AutoLightingPicksRestirForManyLights) {
  PipelineSettings s = small(1);
  s.denoise = false, s.auto_lighting = true, s.max_depth = 2;
  Pipeline hall("builtin:lamp_hall", s);
  EXPECT_EQ(hall.direct_lighting(), DirectLighting::restir);
  EXPECT_EQ(hall.light_sampling(), LightSampling::tree);
  const Asset asset = Asset::load("builtin:lamp_hall");
  const Camera cam = *find_view(asset, "inside");
  Renderer r(asset.scene());
  RenderSettings rs;
  rs.width = 64, rs.height = 48, rs.max_depth = 2, rs.clamp = s.clamp, rs.fixed_jitter = true;
  rs.direct = DirectLighting::restir, rs.light_sampling = LightSampling::tree;
  std::optional<Camera> prev;
  for (uint32_t f = 0; f < 3; ++f) {
    rs.frame = f;
    const Frame want = r.render(cam, rs, prev);
    prev = cam;
    EXPECT_EQ(hall.frame(cam, 0.0).noisy.pixels, want[Aov::color].pixels) << f;
  }
  Pipeline box("builtin:cornell_box", s);
  EXPECT_EQ(box.direct_lighting(), DirectLighting::nee);
  s.auto_lighting = false;
  Pipeline fixed("builtin:lamp_hall", s);
  EXPECT_EQ(fixed.direct_lighting(), DirectLighting::nee);
}

// Automatic exposure: a brighter scene gets fewer stops; the exposure moves 10 % of the way
// per frame towards the log-average target (the first frame jumps there).
TEST(Pipeline, AutoExposureFollowsTheImageSmoothly) {
  PipelineSettings s = small(1);
  s.denoise = false, s.auto_exposure = true;
  Pipeline dim("builtin:cornell_box", s, "none");
  Pipeline bright("builtin:cornell_box", s, "constant:20,20,20");
  const float e_dim = dim.frame(front(), 0.0).exposure,
              e_bright = bright.frame(front(), 0.0).exposure;
  EXPECT_GT(e_dim, e_bright + 1.0f);
  // Steady state: the image does not change much, so the exposure barely moves; a manual
  // exposure is added on top.
  const float e2 = dim.frame(front(), 0.0).exposure;
  EXPECT_NEAR(e2, e_dim, 0.5f);
  s.exposure = 1.0f;
  dim.set_settings(s);
  EXPECT_NEAR(dim.frame(front(), 0.0).exposure, e2 + 1.0f, 0.5f);
  PipelineSettings fixed = small(1);
  fixed.denoise = false;
  EXPECT_EQ(Pipeline("builtin:cornell_box", fixed).frame(front(), 0.0).exposure, 0.0f);
}

TEST(Pipeline, AdaptiveFactorFollowsTheTarget) {
  PipelineSettings s = small(2);
  s.target_ms = 1e-6;  // impossible: fewer first bounces, then coarser
  Pipeline p("builtin:cornell_box", s);
  const std::pair<float, int> down[] = {{0.5f, 2}, {0.25f, 2}, {0.25f, 4}, {0.25f, 4}};
  for (const auto& [rate, factor] : down) {
    p.frame(front(), 0.0);
    EXPECT_EQ(p.settings().indirect_rate, rate);
    EXPECT_EQ(p.settings().factor, factor);
  }
  s.target_ms = 1e6;  // trivially met: the full rate back, then finer, step by step
  s.factor = 4, s.indirect_rate = 0.25f;
  p.set_settings(s);
  const std::pair<float, int> up[] = {{0.5f, 4}, {1.0f, 4}, {1.0f, 2}, {1.0f, 1}, {1.0f, 1}};
  for (const auto& [rate, factor] : up) {
    p.frame(front(), 0.0);
    EXPECT_EQ(p.settings().indirect_rate, rate);
    EXPECT_EQ(p.settings().factor, factor);
  }
}

TEST(Pipeline, ProgressiveReferenceAccumulatesAtRestAndConverges) {
  Pipeline p("builtin:cornell_box", small(2));
  const Camera c = front();
  for (int i = 0; i < 48; ++i) p.accumulate(c, 0.0);
  EXPECT_EQ(p.accumulated(), 48);
  const FloatImage ref48 = p.accumulate(c, 0.0).upscaled;
  // A many-sample render of the same view (another seed) is close; a 1-sample one is not.
  Pipeline q("builtin:cornell_box", small(2));
  PipelineSettings s = small(2);
  s.seed = 99;
  q.set_settings(s);
  for (int i = 0; i < 48; ++i) q.accumulate(c, 0.0);
  const FloatImage other = q.accumulate(c, 0.0).upscaled;
  Camera moved = c;
  moved.eye.x += 0.05f;
  const FloatImage one = p.accumulate(moved, 0.0).upscaled;
  EXPECT_EQ(p.accumulated(), 1);  // the camera moved: restarted
  auto mse = [](const FloatImage& a, const FloatImage& b) {
    double e = 0;
    for (size_t i = 0; i < a.pixels.size(); ++i) {
      const double x = a.pixels[i] / (1 + a.pixels[i]), y = b.pixels[i] / (1 + b.pixels[i]);
      e += (x - y) * (x - y);
    }
    return e / double(a.pixels.size());
  };
  EXPECT_LT(mse(ref48, other), 0.5 * mse(one, other));
}

TEST(Pipeline, ProgressiveReferenceIgnoresTheRadianceCacheAndTheIndirectRate) {
  // The reference at rest is unbiased: the loop's (biased) radiance cache stays out of it, and
  // it traces every pixel's first bounce whatever the loop's frame budget (indirect_rate).
  PipelineSettings s = small(2);
  s.radiance_cache = true;
  s.indirect_rate = 0.5f;
  Pipeline cached("builtin:cornell_box", s);
  s.radiance_cache = false;
  s.indirect_rate = 1.0f;
  Pipeline plain("builtin:cornell_box", s);
  const Camera c = front();
  for (int i = 0; i < 3; ++i) cached.accumulate(c, 0.0), plain.accumulate(c, 0.0);
  EXPECT_EQ(cached.accumulate(c, 0.0).upscaled.pixels, plain.accumulate(c, 0.0).upscaled.pixels);
  // While the loop's frames do use it (fewer rays once the cache knows the cells).
  s.factor = 1, s.radiance_cache = true;
  Pipeline loop("builtin:cornell_box", s);
  uint64_t rays[2] = {0, 0};
  for (int i = 0; i < 4; ++i) rays[i > 0] = loop.frame(c, 0.0).stats.rays();
  EXPECT_LT(rays[1], rays[0]);
}

TEST(Pipeline, BadSettingsAreErrors) {
  PipelineSettings s = small(3);
  EXPECT_THROW(Pipeline("builtin:cornell_box", s), Error);
  s = small(4);
  s.width = 66;
  EXPECT_THROW(Pipeline("builtin:cornell_box", s), Error);
  EXPECT_THROW(Pipeline("/nonexistent/scene.obj", small(2)), Error);
  s = small(2);
  s.spp = 0;
  EXPECT_THROW(Pipeline("builtin:cornell_box", s), Error);
  Pipeline p("builtin:cornell_box", small(2));
  s = small(2);
  s.factor = 8;
  EXPECT_THROW(p.set_settings(s), Error);
  EXPECT_EQ(p.settings().factor, 2);  // unchanged
}

}  // namespace
}  // namespace kestrel
