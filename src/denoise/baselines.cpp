// The baselines written plainly: the edge-avoiding a-trous filter (Dammertz et al. 2010) and
// SVGF-like's scalar definition, the oracle of the real-time Svgf (svgf.cpp).
#include <algorithm>
#include <cmath>

#include "core/parallel.h"
#include "denoise/svgf.h"

namespace kestrel::denoise {

namespace {

template <class F>
void rows(int h, F&& f) {
  parallel_for(0, size_t(h), 4, [&](size_t begin, size_t end) { f(int(begin), int(end)); });
}

const float kB3[5] = {1.0f / 16, 1.0f / 4, 3.0f / 8, 1.0f / 4, 1.0f / 16};  // Dammertz's 5x5
const float kB1[3] = {0.25f, 0.5f, 0.25f};  // SVGF-like's variance blur
const float kBox[3] = {1.0f, 1.0f, 1.0f};   // SVGF-like's 3x3 taps (normalised by the sum)

// One edge-avoiding a-trous pass over planar irradiance `x` (3 channels) and optionally a
// variance plane: taps (2r + 1)^2 with weights kernel[j + r] * kernel[i + r] times the caller's
// per-pixel edge function.
template <class Weight>
void atrous_pass(const Planes& in, Planes& out, const float* kernel, int r, int dilation,
                 const float* var_in, float* var_out, Weight&& weight) {
  const int W = in.width, H = in.height;
  rows(H, [&](int r0, int r1) {
    for (int y = r0; y < r1; ++y)
      for (int x = 0; x < W; ++x) {
        const size_t p = size_t(y) * size_t(W) + size_t(x);
        float acc[3] = {0, 0, 0}, wsum = 0, vacc = 0;
        for (int j = -r; j <= r; ++j) {
          const int qy = y + j * dilation;
          if (qy < 0 || qy >= H) continue;
          for (int i = -r; i <= r; ++i) {
            const int qx = x + i * dilation;
            if (qx < 0 || qx >= W) continue;
            const size_t q = size_t(qy) * size_t(W) + size_t(qx);
            const float w = kernel[j + r] * kernel[i + r] * weight(p, q);
            for (int c = 0; c < 3; ++c) acc[c] += w * in.ch(c)[q];
            wsum += w;
            if (var_in) vacc += w * w * var_in[q];
          }
        }
        for (int c = 0; c < 3; ++c) out.ch(c)[p] = wsum > 0 ? acc[c] / wsum : in.ch(c)[p];
        if (var_out) var_out[p] = wsum > 0 ? vacc / (wsum * wsum) : var_in[p];
      }
  });
}

// x^(2^k) by k squarings (SVGF's normal weight max(0, n.n_q)^128 without pow).
float pow2k(float x, int k) {
  for (int i = 0; i < k; ++i) x *= x;
  return x;
}

float normal_dot(const Planes& g, size_t p, size_t q) {
  return g.ch(6)[p] * g.ch(6)[q] + g.ch(7)[p] * g.ch(7)[q] + g.ch(8)[p] * g.ch(8)[q];
}
float rel_depth(const Planes& g, size_t p, size_t q) {
  return std::abs(g.ch(9)[p] - g.ch(9)[q]) / std::max(g.ch(9)[p], kMinDepth);
}

// SVGF's depth edge stop: |z_p - z_q| / (|grad z(p) . (p - q)| + eps), the screen-space depth
// gradient predicting the depth change along the tap's offset.
struct DepthGradient {
  std::vector<float> gx, gy;
  int width = 0;
  explicit DepthGradient(const Planes& g)
      : gx(size_t(g.width) * size_t(g.height)), gy(gx.size()), width(g.width) {
    depth_gradient(g, gx.data(), gy.data());
  }
  float weight(const Planes& g, size_t p, size_t q, float sigma) const {
    const float dx = float(int(q % size_t(width)) - int(p % size_t(width)));
    const float dy = float(int(q / size_t(width)) - int(p / size_t(width)));
    const float predicted = std::abs(gx[p] * dx + gy[p] * dy);
    return std::abs(g.ch(9)[p] - g.ch(9)[q]) /
           (sigma * predicted + 1e-3f * std::max(g.ch(9)[p], kMinDepth));
  }
};

}  // namespace

// 5 passes, dilation 1..16, colour (log irradiance) / normal / depth (SVGF's gradient-scaled
// form) edge stopping; the colour sigma halves each pass.
Planes atrous_filter(const Planes& g) {
  Planes x, demod, out;
  demodulate(g, x, demod);
  Planes t(g.width, g.height, 3), logx(g.width, g.height, 3);
  const DepthGradient dz(g);
  const float sigma_c = 0.6f, sigma_n = 0.2f, sigma_z = 1.0f;
  for (int it = 0; it < 5; ++it) {
    for (int c = 0; c < 3; ++c)
      for (size_t p = 0; p < size_t(x.width) * size_t(x.height); ++p)
        logx.ch(c)[p] = std::log1p(std::max(x.ch(c)[p], 0.0f));
    const float sc = sigma_c * std::ldexp(1.0f, -it);
    atrous_pass(x, t, kB3, 2, 1 << it, nullptr, nullptr, [&](size_t p, size_t q) {
      float d2 = 0;
      for (int c = 0; c < 3; ++c) {
        const float d = logx.ch(c)[p] - logx.ch(c)[q];
        d2 += d * d;
      }
      const float nd = std::max(0.0f, 1.0f - normal_dot(g, p, q));
      return std::exp(-d2 / (sc * sc) - nd / (sigma_n * sigma_n) - dz.weight(g, p, q, sigma_z));
    });
    std::swap(x, t);
  }
  remodulate(x, demod, out);
  return out;
}

Planes SvgfReference::run(const Planes& g) {
  const int W = g.width, H = g.height;
  const size_t N = size_t(W) * size_t(H);
  Planes x, demod, acc;
  demodulate(g, x, demod);
  std::vector<float> m1(N), m2(N), len(N), var(N);
  svgf_temporal(g, x, history, acc, m1.data(), m2.data(), len.data(), var.data());
  // Short histories: variance from a 7x7 neighbourhood of the moments.
  std::vector<float> var2 = var;
  rows(H, [&](int r0, int r1) {
    for (int y = r0; y < r1; ++y)
      for (int i = 0; i < W; ++i) {
        const size_t p = size_t(y) * size_t(W) + size_t(i);
        if (len[p] >= 4) continue;
        float s1 = 0, s2 = 0, ws = 0;
        for (int j = -3; j <= 3; ++j)
          for (int k = -3; k <= 3; ++k) {
            const int sy = y + j, sx = i + k;
            if (sx < 0 || sy < 0 || sx >= W || sy >= H) continue;
            const size_t q = size_t(sy) * size_t(W) + size_t(sx);
            const float w = std::exp(-rel_depth(g, p, q) / 0.05f) *
                                pow2k(std::max(0.0f, normal_dot(g, p, q)), 5) +
                            (q == p ? 1.0f : 0.0f);
            s1 += w * m1[q], s2 += w * m2[q], ws += w;
          }
        var2[p] = std::max(0.0f, s2 / ws - (s1 / ws) * (s1 / ws)) * 4.0f / len[p];
      }
  });
  var = var2;
  Planes t(W, H, 3);
  std::vector<float> var_next(N), gvar(N);
  const float sigma_l = 4.0f, sigma_z = 1.0f, sigma_n = 128.0f;
  const DepthGradient dz(g);
  Planes first;
  for (int it = 0; it < kSvgfPasses; ++it) {
    // 3x3 Gaussian-blurred variance for the luminance edge stop.
    rows(H, [&](int r0, int r1) {
      for (int y = r0; y < r1; ++y)
        for (int i = 0; i < W; ++i) {
          float s = 0, ws = 0;
          for (int j = -1; j <= 1; ++j)
            for (int k = -1; k <= 1; ++k) {
              const int sy = y + j, sx = i + k;
              if (sx < 0 || sy < 0 || sx >= W || sy >= H) continue;
              const float w = kB1[j + 1] * kB1[k + 1];
              s += w * var[size_t(sy) * size_t(W) + size_t(sx)], ws += w;
            }
          gvar[size_t(y) * size_t(W) + size_t(i)] = s / ws;
        }
    });
    atrous_pass(acc, t, kBox, 1, 1 << it, var.data(), var_next.data(), [&](size_t p, size_t q) {
      const float lp = svgf_luminance(acc.ch(0)[p], acc.ch(1)[p], acc.ch(2)[p]);
      const float lq = svgf_luminance(acc.ch(0)[q], acc.ch(1)[q], acc.ch(2)[q]);
      const float wl = std::abs(lp - lq) / (sigma_l * std::sqrt(gvar[p]) + 1e-4f);
      const float wz = dz.weight(g, p, q, sigma_z);
      const bool no_normal = g.ch(6)[p] == 0 && g.ch(7)[p] == 0 && g.ch(8)[p] == 0;
      // exp(sigma_n (n.n' - 1)): SVGF's max(0, n.n')^sigma_n with log c ~ c - 1, so that
      // one exp carries every edge stop.
      const float ln = no_normal ? 0.0f : sigma_n * (std::max(0.0f, normal_dot(g, p, q)) - 1);
      if (svgf_black(g, p) != svgf_black(g, q)) return 0.0f;  // radiance and irradiance
      return std::exp(ln - wl - wz);
    });
    std::swap(acc, t);
    std::swap(var, var_next);
    if (it == 0) first = acc;
  }
  history = Planes(W, H, 11);
  for (size_t p = 0; p < N; ++p) {
    for (int c = 0; c < 3; ++c) history.ch(c)[p] = first.ch(c)[p];
    history.ch(3)[p] = m1[p], history.ch(4)[p] = m2[p], history.ch(5)[p] = len[p];
    history.ch(6)[p] = g.ch(9)[p];
    for (int c = 0; c < 3; ++c) history.ch(7 + c)[p] = g.ch(6 + c)[p];
    history.ch(10)[p] = svgf_black(g, p) ? 1.0f : 0.0f;
  }
  Planes out;
  remodulate(acc, demod, out);
  return out;
}

}  // namespace kestrel::denoise
