// The environment: constant, CIE overcast sky or an equirectangular image; its importance
// sampling (cosine-weighted for constant ones and smooth skies, by luminance for other
// images) and pdf.
#include <algorithm>
#include <cmath>

#include "render/renderer_impl.h"

namespace kestrel {

using namespace render;

// After the lights are known: the given environment, else the sky unless the scene has lights
// of its own (emission from textures alone does not count: sync_lights).
void Renderer::Impl::choose_environment(std::optional<Environment> environment) {
  if (environment)
    env = std::move(*environment);
  else
    env = Environment::parse(lit_by_emitters ? "none" : "sky");
  setup_environment();
  env_ready = true;
  choose_strategies();
}

void Renderer::Impl::setup_environment() {
  env_on = env.scale > 0 && (!env.image.pixels.empty() || luminance(env.color) > 0);
  env_cosine = env.image.pixels.empty() || env.cosine_sampled;
  env_rows = Distribution1D();
  env_cols.clear();
  env_small.clear();
  env_small_w = env_small_h = 0;
  if (env_cosine && !env.image.pixels.empty()) {
    // Whole source texels per small texel, and the equator on a row boundary of both.
    const int w = env.image.width, h = env.image.height;
    const int fx = std::max(1, w / 128), fy = std::max(1, h / 64);
    if (w % fx == 0 && h % (2 * fy) == 0) {
      env_small_w = w / fx, env_small_h = h / fy;
      env_small.assign(size_t(env_small_w) * size_t(env_small_h) * 3, 0.0f);
      const float inv = 1.0f / float(fx * fy);
      for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x) {
          const float* p = env.image.at(x, y);
          float* q = &env_small[(size_t(y / fy) * size_t(env_small_w) + size_t(x / fx)) * 3];
          for (int c = 0; c < 3; ++c) q[c] += p[c] * inv;
        }
    }
  }
  if (!env_cosine) {
    const int w = env.image.width, h = env.image.height;
    std::vector<float> row_weights(static_cast<size_t>(h), 0.0f);
    for (int y = 0; y < h; ++y) {
      const float sin_theta = std::sin(pi * (float(y) + 0.5f) / float(h));
      std::vector<float> cols(static_cast<size_t>(w), 0.0f);
      for (int x = 0; x < w; ++x) {
        const float* p = env.image.at(x, y);
        cols[size_t(x)] = luminance({p[0], p[1], p[2]}) * sin_theta + 1e-8f;
      }
      env_cols.emplace_back(cols);
      row_weights[size_t(y)] = env_cols.back().total();
    }
    env_rows = Distribution1D(row_weights);
  }
  // Irradiance on a surface facing up (luminance): what the sun's share is weighed against.
  env_irradiance = 0;
  if (env_on) {
    if (!env.image.pixels.empty()) {
      const int w = env.image.width, h = env.image.height;
      double sum = 0;
      for (int y = 0; y < h; ++y) {
        const double theta = pi * (y + 0.5) / h, c = std::cos(theta);
        if (c <= 0) break;
        double row = 0;
        for (int x = 0; x < w; ++x) {
          const float* p = env.image.at(x, y);
          row += luminance({p[0], p[1], p[2]});
        }
        sum += row * c * std::sin(theta) * (2 * pi / w) * (pi / h);
      }
      env_irradiance = float(sum) * env.scale;
    } else {  // constant: pi L; overcast: (1 + 2 cos) / 3 integrates to 7 pi / 9
      env_irradiance = luminance(env.color) * env.scale * (env.overcast ? 7 * pi / 9 : pi);
    }
  }
  sun_on = false;
  if (env.sun) {
    const Sun& sun = *env.sun;
    sun.check();
    const double radius = double(sun.angular_radius_degrees) * 3.14159265358979 / 180.0;
    const double one_minus_cos =
        2 * std::sin(radius / 2) * std::sin(radius / 2);  // 1 - cos, exactly
    sun_dir = normalize(sun.direction);
    sun_frame = Basis(sun_dir);
    sun_cos_max = float(1 - one_minus_cos);
    sun_solid_angle = float(2 * 3.14159265358979 * one_minus_cos);
    sun_radiance = sun.irradiance * (1.0f / sun_solid_angle);
    sun_on = luminance(sun.irradiance) > 0;
  }
}

// NEE's choice among the environment, the sun and the local lights: equal shares of what
// exists (the environment alone: 1; with local lights: 1/2 each, as before the sun existed),
// except that the sun and the environment split their two shares in proportion to their
// irradiance on a surface facing each (the sun: its irradiance; the environment: on an
// upward surface), each keeping at least 1/8 of the pair's: a half-and-half split left half
// the sunlit pixels of a 1-spp frame without the sun, which is most of the light there.
void Renderer::Impl::choose_strategies() {
  const bool local = local_light_count() > 0;
  if (!sun_on) {
    p_sun = 0;
    p_env = !env_on ? 0.0f : (!local ? 1.0f : 0.5f);
    return;
  }
  const float n = float(int(env_on) + 1 + int(local));
  if (!env_on) {
    p_env = 0, p_sun = 1.0f / n;
    return;
  }
  const float es = luminance(sun_radiance) * sun_solid_angle, pair = 2.0f / n;
  const float f = es + env_irradiance > 0 ? es / (es + env_irradiance) : 0.5f;
  p_sun = pair * std::clamp(f, 0.125f, 0.875f);
  p_env = pair - p_sun;
}

Vec3 Renderer::Impl::env_smooth_radiance(float u, float v, bool upper) const {
  const int w = env_small_w, h = env_small_h, half = h / 2;
  const float fx = u * float(w) - 0.5f;
  const float fy = std::clamp(v * float(h) - 0.5f, upper ? 0.0f : float(half),
                              upper ? float(half - 1) : float(h - 1));
  const float x0f = floor_exact(fx), y0f = floor_exact(fy);
  const float tx = fx - x0f, ty = fy - y0f;
  int x0 = int(x0f);
  if (x0 < 0 || x0 >= w) {  // u outside [0, 1]: wrapped (no division in the common case)
    x0 %= w;
    if (x0 < 0) x0 += w;
  }
  const int x1 = x0 + 1 == w ? 0 : x0 + 1;
  const int y0 = int(y0f), y1 = std::min(y0 + 1, upper ? half - 1 : h - 1);
  const float* r0 = &env_small[size_t(y0) * size_t(w) * 3];
  const float* r1 = &env_small[size_t(y1) * size_t(w) * 3];
  const auto channel = [&](int c) {
    const float top = r0[3 * x0 + c] + tx * (r0[3 * x1 + c] - r0[3 * x0 + c]);
    const float bottom = r1[3 * x0 + c] + tx * (r1[3 * x1 + c] - r1[3 * x0 + c]);
    return top + ty * (bottom - top);
  };
  return {channel(0), channel(1), channel(2)};
}

// Solid-angle pdf of sampling direction d from the environment (given it was chosen), at a
// point with shading normal n: a constant environment or a smooth sky is sampled
// cosine-weighted about n (every sample above the surface), other images by their luminance.
// (The physical sky by luminance: 10-15 % of a frame inside Sponza went to the CDF searches
// and their cache misses, and ~60 % of its samples fell below the surface.)
float Renderer::Impl::env_pdf(Vec3 d, Vec3 n) const {
  if (env_cosine) return std::max(0.0f, dot(d, n)) / pi;
  // The same texel as env_radiance (render/fast_math.h).
  const float u = 0.5f + atan2_fast(d.x, -d.z) * (1 / (2 * pi));
  const float theta = acos_fast(std::clamp(d.y, -1.0f, 1.0f));
  const int w = env.image.width, h = env.image.height;
  const int x = std::clamp(int(u * float(w)), 0, w - 1);
  const int y = std::clamp(int(theta / pi * float(h)), 0, h - 1);
  const float sin_theta = std::sin(theta);
  if (sin_theta <= 0) return 0;
  const float pdf_uv =
      env_rows.pmf(size_t(y)) * env_cols[size_t(y)].pmf(size_t(x)) * float(w) * float(h);
  return pdf_uv / (2 * pi * pi * sin_theta);
}

Vec3 Renderer::Impl::env_sample(float u1, float u2, Vec3 n, float& pdf) const {
  if (env_cosine) {
    const float r = std::sqrt(u1);
    float sin_phi, cos_phi;  // of phi = 2 pi u2
    sincos_2pi(u2, sin_phi, cos_phi);
    const Vec3 local{r * cos_phi, r * sin_phi, std::sqrt(std::max(0.0f, 1.0f - u1))};
    const Vec3 d = Basis(n).to_world(local);
    pdf = env_pdf(d, n);
    return d;
  }
  float ru, cu;
  const size_t y = env_rows.sample(u1, &ru);
  const size_t x = env_cols[y].sample(u2, &cu);
  const float u = (float(x) + cu) / float(env.image.width);
  const float v = (float(y) + ru) / float(env.image.height);
  const float theta = v * pi, phi = (u - 0.5f) * 2 * pi;
  const Vec3 d{std::sin(theta) * std::sin(phi), std::cos(theta), -std::sin(theta) * std::cos(phi)};
  pdf = env_pdf(d, n);
  return d;
}

}  // namespace kestrel
