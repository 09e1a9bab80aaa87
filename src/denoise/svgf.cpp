// SVGF-like in real time (svgf.h): the frame's passes over reused buffers, the hot loops per
// ISA in svgf_kernels.inl; and the steps both SVGF forms and the a-trous filter share.
#include "denoise/svgf.h"

#include <algorithm>
#include <cmath>
#include <cstring>

#include "core/parallel.h"
#include "core/timer.h"
#include "kestrel/isa.h"

namespace kestrel::denoise {

namespace {

template <class F>
void rows(int h, F&& f) {
  parallel_for(0, size_t(h), 4, [&](size_t begin, size_t end) { f(int(begin), int(end)); });
}

void ensure(Planes& p, int w, int h, int c) {
  if (p.width != w || p.height != h || p.channels != c) p = Planes(w, h, c);
}

}  // namespace

const SvgfKernels& svgf_kernels() {
  switch (default_isa()) {
    case Isa::avx512:
      return svgf_kernels_avx512();
    case Isa::avx2:
      return svgf_kernels_avx2();
    default:
      return svgf_kernels_sse2();
  }
}

// By albedo, except where the albedo is (nearly) black (emitters, black surfaces): there the
// colour is filtered as it is, since dividing by ~0 would turn it into huge irradiance that
// the filters then spread onto lit neighbours.
void demodulate(const Planes& g, Planes& x, Planes& demod, float* black_out, uint8_t* black_rows) {
  const int W = g.width, H = g.height;
  ensure(x, W, H, 3);
  ensure(demod, W, H, 3);
  const float *C0 = g.ch(0), *C1 = g.ch(1), *C2 = g.ch(2);
  const float *B0 = g.ch(3), *B1 = g.ch(4), *B2 = g.ch(5);
  float *X0 = x.ch(0), *X1 = x.ch(1), *X2 = x.ch(2);
  float *D0 = demod.ch(0), *D1 = demod.ch(1), *D2 = demod.ch(2);
  rows(H, [&](int r0, int r1) {
    for (int y = r0; y < r1; ++y) {
      bool any = false;
      for (size_t p = size_t(y) * size_t(W); p < size_t(y + 1) * size_t(W); ++p) {
        const float a0 = B0[p], a1 = B1[p], a2 = B2[p];
        const bool black = black_albedo(a0, a1, a2);
        any |= black;
        if (black_out) black_out[p] = black ? 1.0f : 0.0f;
        const float d0 = black ? 1.0f : std::max(a0, 0.0f) + kAlbedoEps;
        const float d1 = black ? 1.0f : std::max(a1, 0.0f) + kAlbedoEps;
        const float d2 = black ? 1.0f : std::max(a2, 0.0f) + kAlbedoEps;
        D0[p] = d0, D1[p] = d1, D2[p] = d2;
        X0[p] = C0[p] / d0, X1[p] = C1[p] / d1, X2[p] = C2[p] / d2;
      }
      if (black_rows) black_rows[y] = any;
    }
  });
}

void remodulate(const Planes& x, const Planes& demod, Planes& out) {
  ensure(out, x.width, x.height, 3);
  const size_t W = size_t(x.width);
  rows(x.height, [&](int r0, int r1) {
    for (int c = 0; c < 3; ++c) {
      const float *xc = x.ch(c), *dc = demod.ch(c);
      float* oc = out.ch(c);
      for (size_t i = size_t(r0) * W; i < size_t(r1) * W; ++i)
        oc[i] = std::max(xc[i], 0.0f) * dc[i];
    }
  });
}

void svgf_temporal(const Planes& g, const Planes& x, const Planes& history, Planes& acc, float* m1,
                   float* m2, float* len, float* var) {
  const int W = g.width, H = g.height;
  const bool have = history.width == W && history.height == H;
  ensure(acc, W, H, 3);
  const float *X0 = x.ch(0), *X1 = x.ch(1), *X2 = x.ch(2), *Z = g.ch(9);
  const float *N0 = g.ch(6), *N1 = g.ch(7), *N2 = g.ch(8), *MX = g.ch(11), *MY = g.ch(12);
  float *A0 = acc.ch(0), *A1 = acc.ch(1), *A2 = acc.ch(2);
  const float* hist[11] = {};
  if (have)
    for (int c = 0; c < 11; ++c) hist[c] = history.ch(c);
  rows(H, [&](int r0, int r1) {
    for (int y = r0; y < r1; ++y)
      for (int i = 0; i < W; ++i) {
        const size_t p = size_t(y) * size_t(W) + size_t(i);
        const float x0 = X0[p], x1 = X1[p], x2 = X2[p];
        const float l = svgf_luminance(x0, x1, x2);
        float h[5] = {0, 0, 0, 0, 0}, hl = 0;
        if (have) {
          // Bilinear reprojection using only the consistent taps (depth within 10 %,
          // normals within ~25 degrees).
          const float px = float(i) + MX[p], py = float(y) + MY[p];
          const int x0i = int(std::floor(px)), y0i = int(std::floor(py));
          const float fx = px - float(x0i), fy = py - float(y0i);
          const float z = Z[p], n0 = N0[p], n1 = N1[p], n2 = N2[p];
          const bool no_normal = n0 == 0 && n1 == 0 && n2 == 0;
          const float black = svgf_black(g, p) ? 1.0f : 0.0f;
          const float zmax = 0.1f * std::max(z, kMinDepth);
          float wsum = 0;
          for (int k = 0; k < 4; ++k) {
            const int sx = x0i + (k & 1), sy = y0i + (k >> 1);
            if (sx < 0 || sy < 0 || sx >= W || sy >= H) continue;
            const size_t q = size_t(sy) * size_t(W) + size_t(sx);
            const float nd = n0 * hist[7][q] + n1 * hist[8][q] + n2 * hist[9][q];
            if (std::abs(hist[6][q] - z) > zmax || !(no_normal || nd > 0.9f) ||
                hist[10][q] != black)
              continue;
            const float w = ((k & 1) ? fx : 1 - fx) * ((k >> 1) ? fy : 1 - fy);
            for (int c = 0; c < 5; ++c) h[c] += w * hist[c][q];
            hl += w * hist[5][q];
            wsum += w;
          }
          if (wsum > 1e-3f) {
            for (float& v : h) v /= wsum;
            hl /= wsum;
          } else {
            hl = 0;
          }
        }
        const float n = std::min(hl, 254.0f) + 1.0f;
        const float a = std::max(1.0f / n, 0.2f);
        const bool keep = hl > 0;
        A0[p] = keep ? h[0] + a * (x0 - h[0]) : x0;
        A1[p] = keep ? h[1] + a * (x1 - h[1]) : x1;
        A2[p] = keep ? h[2] + a * (x2 - h[2]) : x2;
        const float mm1 = keep ? h[3] + a * (l - h[3]) : l;
        const float mm2 = keep ? h[4] + a * (l * l - h[4]) : l * l;
        m1[p] = mm1, m2[p] = mm2, len[p] = n;
        var[p] = std::max(0.0f, mm2 - mm1 * mm1);
      }
  });
}

void depth_gradient(const Planes& g, float* gx, float* gy) {
  const int W = g.width, H = g.height;
  const float* z = g.ch(9);
  rows(H, [&](int r0, int r1) {
    for (int y = r0; y < r1; ++y) {
      // Central differences inside, one-sided at the borders (0 across a 1-pixel image).
      const float* zr = z + size_t(y) * size_t(W);
      const float* zu = z + size_t(std::max(y - 1, 0)) * size_t(W);
      const float* zd = z + size_t(std::min(y + 1, H - 1)) * size_t(W);
      float* ox = gx + size_t(y) * size_t(W);
      float* oy = gy + size_t(y) * size_t(W);
      const float sy = (y > 0 && y + 1 < H) ? 0.5f : 1.0f;
      for (int x = 0; x < W; ++x) oy[x] = (zd[x] - zu[x]) * sy;
      for (int x = 1; x + 1 < W; ++x) ox[x] = (zr[x + 1] - zr[x - 1]) * 0.5f;
      ox[0] = W > 1 ? zr[1] - zr[0] : 0.0f;
      if (W > 1) ox[W - 1] = zr[W - 1] - zr[W - 2];
    }
  });
}

const Planes& Svgf::run(const Planes& g, SvgfTimes* times) {
  copy_ = g;
  Timer timer;
  const Planes& x = filter(copy_, times);
  remodulate(x, demod_, out_);
  if (times) times->output = timer.ms() - times->temporal - times->variance - times->passes;
  return out_;
}

void Svgf::run_taking(Planes& g, FloatImage& out, SvgfTimes* times) {
  Timer timer;
  const int w = g.image_width > 0 ? g.image_width : g.width,
            h = g.image_height > 0 ? g.image_height : g.height;
  const Planes& x = filter(g, times);  // g is the frame before's afterwards
  if (out.width != w || out.height != h || out.channels != 3) out = FloatImage(w, h, 3);
  const size_t W = size_t(x.width);
  rows(h, [&](int r0, int r1) {
    for (int y = r0; y < r1; ++y) {
      const size_t b = size_t(y) * W;
      const float *x0 = x.ch(0) + b, *x1 = x.ch(1) + b, *x2 = x.ch(2) + b;
      const float *d0 = demod_.ch(0) + b, *d1 = demod_.ch(1) + b, *d2 = demod_.ch(2) + b;
      float* o = out.at(0, y);
      for (int i = 0; i < w; ++i) {
        o[3 * i] = std::max(x0[i], 0.0f) * d0[i];
        o[3 * i + 1] = std::max(x1[i], 0.0f) * d1[i];
        o[3 * i + 2] = std::max(x2[i], 0.0f) * d2[i];
      }
    }
  });
  if (times) times->output = timer.ms() - times->temporal - times->variance - times->passes;
}

const Planes& Svgf::filter(Planes& g, SvgfTimes* times) {
  Timer timer;
  double last = 0;
  auto lap = [&](double SvgfTimes::*slot) {
    const double now = timer.ms();
    if (times) times->*slot = now - last;
    last = now;
  };
  const int W = g.width, H = g.height;
  ensure(next_, W, H, 6);
  ensure(tmp_, W, H, 3);
  ensure(aux_, W, H, 6);  // planes, not separate vectors: see Planes on cache sets
  ensure(black_, W, H, 1);
  float *var = aux_.ch(0), *lum = aux_.ch(1), *var2 = aux_.ch(2), *lum2 = aux_.ch(3);
  float *gx = aux_.ch(4), *gy = aux_.ch(5), *black = black_.ch(0);
  black_rows_.resize(size_t(H));
  const SvgfKernels& k = svgf_kernels();
  ensure(x_, W, H, 3);
  ensure(demod_, W, H, 3);
  SvgfDemodulate de;
  for (int c = 0; c < 3; ++c)
    de.color[c] = g.ch(c), de.albedo[c] = g.ch(3 + c), de.x[c] = x_.ch(c), de.d[c] = demod_.ch(c);
  de.black = black, de.black_rows = black_rows_.data(), de.width = W;
  rows(H, [&](int r0, int r1) { k.demodulate(de, r0, r1); });
  if (history_.width != W || history_.height != H) {  // the first frame
    svgf_temporal(g, x_, Planes(), acc_, next_.ch(3), next_.ch(4), next_.ch(5), var);
  } else {
    ensure(acc_, W, H, 3);
    // The history as SvgfTemporal reads it: irradiance, moments and length from the last
    // frame's pass, depth, normals and black flags from its inputs.
    const float* hist[11] = {history_.ch(0),  history_.ch(1),       history_.ch(2),
                             history_.ch(3),  history_.ch(4),       history_.ch(5),
                             previous_.ch(9), previous_.ch(6),      previous_.ch(7),
                             previous_.ch(8), previous_black_.ch(0)};
    SvgfTemporal te;
    for (int c = 0; c < 3; ++c) te.x[c] = x_.ch(c), te.n[c] = g.ch(6 + c), te.acc[c] = acc_.ch(c);
    te.z = g.ch(9), te.mx = g.ch(11), te.my = g.ch(12), te.black = black, te.hist = hist;
    te.m1 = next_.ch(3), te.m2 = next_.ch(4), te.len = next_.ch(5), te.var = var;
    te.width = W, te.height = H;
    rows(H, [&](int r0, int r1) { k.temporal(te, r0, r1); });
  }
  lap(&SvgfTimes::temporal);
  SvgfVariance va;
  va.m1 = next_.ch(3), va.m2 = next_.ch(4), va.len = next_.ch(5), va.var = var;
  va.z = g.ch(9);
  for (int c = 0; c < 3; ++c) va.n[c] = g.ch(6 + c);
  va.out = var2, va.width = W, va.height = H;
  rows(H, [&](int r0, int r1) { k.variance(va, r0, r1); });
  std::swap(var, var2);
  depth_gradient(g, gx, gy);
  lap(&SvgfTimes::variance);
  rows(H, [&](int r0, int r1) {
    const float *a0 = acc_.ch(0), *a1 = acc_.ch(1), *a2 = acc_.ch(2);
    for (size_t p = size_t(r0) * size_t(W); p < size_t(r1) * size_t(W); ++p)
      lum[p] = svgf_luminance(a0[p], a1[p], a2[p]);
  });
  // Pass 0 writes the next history's irradiance, which pass 1 reads; then tmp_ and acc_ in
  // turn.
  const Planes* in = &acc_;
  for (int it = 0; it < kSvgfPasses; ++it) {
    Planes& out = it == 0 ? next_ : in == &tmp_ ? acc_ : tmp_;
    SvgfPass pa;
    for (int c = 0; c < 3; ++c) pa.x[c] = in->ch(c), pa.n[c] = g.ch(6 + c), pa.out[c] = out.ch(c);
    pa.lum = lum, pa.var = var, pa.z = g.ch(9);
    pa.gx = gx, pa.gy = gy, pa.black = black, pa.black_rows = black_rows_.data();
    pa.lum_out = lum2, pa.var_out = var2;
    pa.width = W, pa.height = H, pa.dilation = 1 << it;
    rows(H, [&](int r0, int r1) { k.pass(pa, r0, r1); });
    std::swap(var, var2);
    std::swap(lum, lum2);
    in = &out;
  }
  lap(&SvgfTimes::passes);
  // The next frame's history: this frame's inputs and black flags are kept, not copied.
  std::swap(history_, next_);
  std::swap(previous_, g);
  std::swap(previous_black_, black_);
  return in == &next_ ? history_ : *in;  // (a single pass's output is the history)
}

}  // namespace kestrel::denoise
