// Built against the public include/ folder only (no kestrel_internal): every public header
// compiles on its own, and the one scene model is usable end to end from the API alone —
// load, render, denoise, upsample, and the frame loop.
#include <gtest/gtest.h>

#include <cmath>

#include "kestrel/kestrel.h"

namespace kestrel {
namespace {

TEST(PublicApi, LoadRenderDenoiseUpsampleFromTheHeadersAlone) {
  const Asset asset = Asset::load("builtin:cornell_box");
  Renderer renderer(asset.scene());
  const std::optional<Camera> camera = find_view(asset, "framing");
  ASSERT_TRUE(camera.has_value());
  RenderSettings s;
  s.width = 32, s.height = 24, s.spp = 2, s.fixed_jitter = true;
  const Frame f = renderer.render(*camera, s);
  double sum = 0;
  for (float v : f[Aov::color].pixels) {
    ASSERT_TRUE(std::isfinite(v));
    sum += v;
  }
  EXPECT_GT(sum, 0);  // the Cornell box's light is seen
  Denoiser d(DenoiserOptions{.method = DenoiseMethod::atrous});
  const FloatImage denoised = d.denoise({&f[Aov::color], &f[Aov::albedo], &f[Aov::normal],
                                         &f[Aov::depth], &f[Aov::roughness], &f[Aov::motion]});
  EXPECT_EQ(denoised.width, 32);
  UpscalerOptions uo;
  uo.method = UpscaleMethod::bicubic, uo.factor = 2;
  Upscaler u(uo);
  const FloatImage up =
      u.upscale({&denoised, &f[Aov::depth], &f[Aov::motion], f.jitter_x, f.jitter_y});
  EXPECT_EQ(up.width, 64);
  PipelineSettings ps;
  ps.width = 32, ps.height = 24, ps.factor = 2, ps.denoiser = DenoiseMethod::atrous,
  ps.upscaler = UpscaleMethod::bilinear;
  Pipeline p("builtin:cornell_box", ps);
  EXPECT_EQ(p.frame(*camera, 0.0).rgb8.size(), size_t(32 * 24 * 3));
}

}  // namespace
}  // namespace kestrel
