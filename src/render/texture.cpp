// Texel fetches: bilinear, repeat-wrapped, sRGB decoded through a table.
#include <algorithm>
#include <cmath>

#include "core/color.h"
#include "render/fast_math.h"
#include "render/renderer_impl.h"

namespace kestrel::render {

namespace {
struct SrgbTable {
  float v[256];
  SrgbTable() {
    for (int i = 0; i < 256; ++i) v[i] = srgb_to_linear(float(i) / 255.0f);
  }
};
const SrgbTable srgb_table;

}  // namespace

const float* srgb_decode_table() {
  return srgb_table.v;
}

namespace {
// The four texels around uv (bilinear, repeat-wrapped) and their weights.
struct Footprint {
  const uint8_t *t00, *t10, *t01, *t11;
  float w00, w10, w01, w11;
  Footprint(const Texture& tex, Vec2 uv) {
    float x = (uv.x - floor_exact(uv.x)) * float(tex.width) - 0.5f;
    float y = (uv.y - floor_exact(uv.y)) * float(tex.height) - 0.5f;
    if (!(x >= -1.0f && x < float(tex.width)) || !(y >= -1.0f && y < float(tex.height)))
      x = 0, y = 0;  // NaN uv
    const float fx = floor_exact(x), fy = floor_exact(y);
    const float wx = x - fx, wy = y - fy;
    // x in [-0.5, w - 0.5): the left texel is -1 (wraps to w - 1) .. w - 1, the right 0 .. w.
    int x0 = int(fx), y0 = int(fy);
    int x1 = x0 + 1, y1 = y0 + 1;
    if (x0 < 0) x0 = tex.width - 1;
    if (x1 >= tex.width) x1 = 0;
    if (y0 < 0) y0 = tex.height - 1;
    if (y1 >= tex.height) y1 = 0;
    const uint8_t* row0 = &tex.rgba[size_t(y0) * size_t(tex.width) * 4];
    const uint8_t* row1 = &tex.rgba[size_t(y1) * size_t(tex.width) * 4];
    t00 = row0 + size_t(x0) * 4, t10 = row0 + size_t(x1) * 4;
    t01 = row1 + size_t(x0) * 4, t11 = row1 + size_t(x1) * 4;
    w00 = (1 - wx) * (1 - wy), w10 = wx * (1 - wy), w01 = (1 - wx) * wy, w11 = wx * wy;
  }
  float linear(int c) const {
    return (float(t00[c]) * w00 + float(t10[c]) * w10 + float(t01[c]) * w01 + float(t11[c]) * w11) *
           (1.0f / 255.0f);
  }
};
}  // namespace

void sample_texture(const Texture& tex, Vec2 uv, bool srgb, float out[3]) {
  const Footprint f(tex, uv);
  if (srgb) {
    const float* lut = srgb_table.v;
    for (int c = 0; c < 3; ++c)
      out[c] = lut[f.t00[c]] * f.w00 + lut[f.t10[c]] * f.w10 + lut[f.t01[c]] * f.w01 +
               lut[f.t11[c]] * f.w11;
  } else {
    for (int c = 0; c < 3; ++c) out[c] = f.linear(c);
  }
}

float sample_channel(const Texture& tex, Vec2 uv, int channel) {
  return Footprint(tex, uv).linear(channel);
}

Vec2 uv_at(const TriangleMesh& m, uint32_t prim, float b1, float b2) {
  if (m.uvs.empty()) return {0, 0};
  const size_t tri = 3 * size_t(prim);
  const Vec2 a = m.uvs[m.indices[tri]], b = m.uvs[m.indices[tri + 1]],
             c = m.uvs[m.indices[tri + 2]];
  const float b0 = 1 - b1 - b2;
  return {a.x * b0 + b.x * b1 + c.x * b2, a.y * b0 + b.y * b1 + c.y * b2};
}

Vec3 mean_texel(const Texture& tex, const TriangleMesh& m, uint32_t prim) {
  // A triangle's texels by a folded n x n grid (twice the triangle's area in texels, at most
  // 16 x 16 samples): cells past the diagonal are mirrored into the triangle.
  const Vec2 a = uv_at(m, prim, 0, 0), b = uv_at(m, prim, 1, 0), c = uv_at(m, prim, 0, 1);
  const double texels =
      0.5 *
      std::fabs(double(b.x - a.x) * double(c.y - a.y) - double(c.x - a.x) * double(b.y - a.y)) *
      double(tex.width) * double(tex.height);
  const int n =
      std::isfinite(texels) ? int(std::clamp(std::ceil(std::sqrt(2 * texels)), 1.0, 16.0)) : 1;
  double sum[3] = {0, 0, 0};
  for (int i = 0; i < n; ++i)
    for (int j = 0; j < n; ++j) {
      float u = (float(i) + 0.5f) / float(n), v = (float(j) + 0.5f) / float(n);
      if (u + v > 1) u = 1 - u, v = 1 - v;
      float px[3];
      sample_texture(tex, uv_at(m, prim, u, v), true, px);
      for (int k = 0; k < 3; ++k) sum[k] += px[k];
    }
  const double inv = 1.0 / double(n * n);
  return {float(sum[0] * inv), float(sum[1] * inv), float(sum[2] * inv)};
}

}  // namespace kestrel::render
