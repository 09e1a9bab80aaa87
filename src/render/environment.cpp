// The environment: constant, CIE overcast sky or an equirectangular image; its importance
// sampling (cosine-weighted for constant ones, by luminance for images) and pdf.
#include <algorithm>
#include <cmath>

#include "render/renderer_impl.h"

namespace kestrel {

using namespace render;

// After the lights are known: the given environment, else the sky when nothing emits.
void Renderer::Impl::choose_environment(std::optional<Environment> environment) {
  if (environment)
    env = std::move(*environment);
  else
    env = Environment::parse(lights.empty() ? "sky" : "none");
  setup_environment();
}

void Renderer::Impl::setup_environment() {
  env_on = env.scale > 0 && (!env.image.pixels.empty() || luminance(env.color) > 0);
  if (!env.image.pixels.empty()) {
    const int w = env.image.width, h = env.image.height;
    std::vector<float> row_weights(static_cast<size_t>(h), 0.0f);
    env_cols.clear();
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
  p_env = !env_on ? 0.0f : (lights.empty() ? 1.0f : 0.5f);
}

// Solid-angle pdf of sampling direction d from the environment (given it was chosen), at a
// point with shading normal n: a constant environment is sampled cosine-weighted about n
// (every sample above the surface), an image by its luminance.
float Renderer::Impl::env_pdf(Vec3 d, Vec3 n) const {
  if (env.image.pixels.empty()) return std::max(0.0f, dot(d, n)) / pi;
  const float u = 0.5f + std::atan2(d.x, -d.z) / (2 * pi);
  const float theta = std::acos(std::clamp(d.y, -1.0f, 1.0f));
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
  if (env.image.pixels.empty()) {
    const float r = std::sqrt(u1), phi = 2 * pi * u2;
    const Vec3 local{r * std::cos(phi), r * std::sin(phi), std::sqrt(std::max(0.0f, 1.0f - u1))};
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
