// Image-quality measures shared by the evaluation programs (image_metrics.h).
#include "image_metrics.h"

#include <algorithm>
#include <cmath>

#include "kestrel/render.h"

namespace kestrel::bench {

std::vector<float> tonemapped(const FloatImage& img) {
  std::vector<float> out(size_t(img.width) * size_t(img.height) * 3);
  for (size_t p = 0; p < size_t(img.width) * size_t(img.height); ++p)
    for (int c = 0; c < 3; ++c)
      out[p * 3 + size_t(c)] = tonemap_aces_srgb(img.pixels[p * size_t(img.channels) + size_t(c)]);
  return out;
}

double psnr(const std::vector<float>& a, const std::vector<float>& b) {
  double mse = 0;
  for (size_t i = 0; i < a.size(); ++i) mse += double(a[i] - b[i]) * double(a[i] - b[i]);
  mse /= double(a.size());
  return 10.0 * std::log10(1.0 / std::max(mse, 1e-12));
}

double ssim(const std::vector<float>& a, const std::vector<float>& b, int w, int h) {
  const int r = 5;
  float g[11];
  float gs = 0;
  for (int i = -r; i <= r; ++i) gs += (g[i + r] = std::exp(-float(i * i) / (2 * 1.5f * 1.5f)));
  for (float& v : g) v /= gs;
  const double c1 = 0.01 * 0.01, c2 = 0.03 * 0.03;
  double total = 0;
  for (int c = 0; c < 3; ++c) {
    // Separable blur of a, b, a^2, b^2, ab.
    std::vector<float> maps[5], tmp(size_t(w) * size_t(h));
    for (auto& m : maps) m.assign(size_t(w) * size_t(h), 0.0f);
    auto val = [&](int k, size_t p) {
      const float x = a[p * 3 + size_t(c)], y = b[p * 3 + size_t(c)];
      return k == 0 ? x : k == 1 ? y : k == 2 ? x * x : k == 3 ? y * y : x * y;
    };
    for (int k = 0; k < 5; ++k) {
      for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x) {
          float s = 0;
          for (int i = -r; i <= r; ++i)
            s += g[i + r] * val(k, size_t(y) * size_t(w) + size_t(std::clamp(x + i, 0, w - 1)));
          tmp[size_t(y) * size_t(w) + size_t(x)] = s;
        }
      for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x) {
          float s = 0;
          for (int i = -r; i <= r; ++i)
            s += g[i + r] * tmp[size_t(std::clamp(y + i, 0, h - 1)) * size_t(w) + size_t(x)];
          maps[k][size_t(y) * size_t(w) + size_t(x)] = s;
        }
    }
    double sum = 0;
    for (size_t p = 0; p < size_t(w) * size_t(h); ++p) {
      const double ma = maps[0][p], mb = maps[1][p];
      const double va = maps[2][p] - ma * ma, vb = maps[3][p] - mb * mb, cov = maps[4][p] - ma * mb;
      sum += ((2 * ma * mb + c1) * (2 * cov + c2)) / ((ma * ma + mb * mb + c1) * (va + vb + c2));
    }
    total += sum / double(size_t(w) * size_t(h));
  }
  return total / 3.0;
}

double relmse(const FloatImage& o, const FloatImage& r) {
  double s = 0;
  size_t n = 0;
  for (size_t p = 0; p < size_t(o.width) * size_t(o.height); ++p)
    for (int c = 0; c < 3; ++c) {
      const double a = o.pixels[p * 3 + size_t(c)],
                   b = r.pixels[p * size_t(r.channels) + size_t(c)];
      s += (a - b) * (a - b) / (b * b + 1e-2);
      ++n;
    }
  return s / double(n);
}

double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v[v.size() / 2];
}

void write_crop_png(const std::string& path, const std::vector<const FloatImage*>& images, int x0,
                    int y0, int cw, int ch) {
  const int scale = 2, W = cw * scale * int(images.size()) + 4 * int(images.size() - 1),
            H = ch * scale;
  std::vector<uint8_t> rgb(size_t(W) * size_t(H) * 3, 255);
  for (size_t k = 0; k < images.size(); ++k)
    for (int y = 0; y < H; ++y)
      for (int x = 0; x < cw * scale; ++x) {
        const FloatImage& img = *images[k];
        const float* px = img.at(std::min(x0 + x / scale, img.width - 1),
                                 std::min(y0 + y / scale, img.height - 1));
        uint8_t* o = &rgb[(size_t(y) * size_t(W) + size_t(int(k) * (cw * scale + 4) + x)) * 3];
        for (int c = 0; c < 3; ++c) o[c] = uint8_t(std::lround(255.0f * tonemap_aces_srgb(px[c])));
      }
  write_png(path, W, H, rgb);
}

}  // namespace kestrel::bench
