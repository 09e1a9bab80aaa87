// The nsrr family's shared parts (nsrr_parts.h).
#include "upscale/nsrr_parts.h"

#include <algorithm>
#include <cmath>

#include "core/parallel.h"
#include "upscale/nsrr_warp.h"

namespace kestrel::upscale::nsrr {

namespace {
constexpr float kMaxMotion = 65536.0f;
float finite_or_zero(float v) {
  return std::isfinite(v) ? v : 0.0f;
}
// Pixel p of a channels-last RGB image into planar y (nsrr.clean + model.to_y): NaN/Inf and
// negative channels read as 0, then c / (1 + L(c)).
void to_y_planar(const float* rgb, size_t p, float* y, size_t plane) {
  float c[3];
  for (size_t k = 0; k < 3; ++k) c[k] = std::max(finite_or_zero(rgb[3 * p + k]), 0.0f);
  const float s = 1.0f / (1.0f + luma(c));
  for (size_t k = 0; k < 3; ++k) y[k * plane + p] = c[k] * s;
}
}  // namespace

using dnnl::memory;
using tag = memory::format_tag;
using dt = memory::data_type;

float Window::push(const UpscaleInput& in, int f, int previous) {
  const int w = in.color->width, h = in.color->height, W = f * w, H = f * h;
  const size_t n = size_t(w) * size_t(h), N = size_t(W) * size_t(H);
  Frame fr = frames_.size() > size_t(previous) ? std::move(frames_.back()) : Frame{};
  if (frames_.size() > size_t(previous)) frames_.pop_back();
  fr.w = w, fr.h = h, fr.jx = in.jitter_x, fr.jy = in.jitter_y;
  // y padded: a vector load at any of its pixels stays inside (reconstruct.h: kMaxLanes).
  fr.y.resize(3 * n + kMaxLanes), fr.depth.resize(n), fr.motion.resize(2 * n),
      fr.sample_at.resize(N);
  const int mc = in.motion ? in.motion->channels : 0;
  // Per row: the depth sum and count (summed in row order after: the same at any thread count).
  std::vector<double> row_sum(static_cast<size_t>(h));
  std::vector<size_t> row_count(static_cast<size_t>(h));
  parallel_for(0, size_t(h), 4, [&](size_t j0, size_t j1) {
    for (size_t j = j0; j < j1; ++j) {
      double sum = 0;
      size_t count = 0;
      for (size_t p = j * size_t(w); p < (j + 1) * size_t(w); ++p) {
        to_y_planar(in.color->pixels.data(), p, fr.y.data(), n);
        const float z = in.depth ? std::max(finite_or_zero(in.depth->pixels[p]), 0.0f) : 1.0f;
        fr.depth[p] = z;
        if (z > 0) sum += double(z), ++count;
        for (size_t k = 0; k < 2; ++k)
          fr.motion[k * n + p] =
              mc ? std::clamp(finite_or_zero(in.motion->pixels[size_t(mc) * p + k]), -kMaxMotion,
                              kMaxMotion)
                 : 0.0f;
      }
      row_sum[j] = sum, row_count[j] = count;
    }
  });
  double depth_sum = 0;
  size_t depth_count = 0;
  for (size_t j = 0; j < size_t(h); ++j) depth_sum += row_sum[j], depth_count += row_count[j];
  // zero_upsample: the sample of low-res pixel (i, j) lands in the output pixel containing it;
  // with a jitter outside [0, 1) clamped samples share a pixel, the last one in row-major
  // order kept: the largest row and the largest column that land there, so the columns and
  // rows are tabled apart.
  fr.col_padded.assign(size_t(W) + 2 * Frame::kColPad, -1), fr.row_at.assign(size_t(H), -1);
  int32_t* col_at = fr.col_padded.data() + Frame::kColPad;
  for (int i = 0; i < w; ++i)
    col_at[clampi(floor_int(float(f) * (float(i) + fr.jx)), 0, W - 1)] = i;
  for (int j = 0; j < h; ++j)
    fr.row_at[size_t(clampi(floor_int(float(f) * (float(j) + fr.jy)), 0, H - 1))] = j;
  parallel_for(0, size_t(H), 16, [&](size_t Y0, size_t Y1) {
    for (size_t Y = Y0; Y < Y1; ++Y) {
      int32_t* at = &fr.sample_at[Y * size_t(W)];
      const int32_t j = fr.row_at[Y];
      if (j < 0) {
        std::fill(at, at + W, -1);
        continue;
      }
      for (size_t X = 0; X < size_t(W); ++X) {
        const int32_t i = col_at[X];
        at[X] = i < 0 ? -1 : j * w + i;
      }
    }
  });
  frames_.push_front(std::move(fr));
  return depth_count ? float(depth_sum / double(depth_count)) : 1.0f;
}

void warp_row_scalar(const WarpRow& a, float* pos, int32_t* out) {
  for (size_t X = 0; X < size_t(a.W); ++X) {
    float& px = pos[2 * X];
    float& py = pos[2 * X + 1];
    // bilinear_at(m, px / f, py / f): edges clamped, pixel centres at i + 0.5.
    const float xf = px * a.inv_f - 0.5f, yf = py * a.inv_f - 0.5f;
    const int x0 = floor_int(xf), y0 = floor_int(yf);
    const float tx = xf - float(x0), ty = yf - float(y0);
    const size_t i0 = size_t(clampi(x0, 0, a.w - 1)), i1 = size_t(clampi(x0 + 1, 0, a.w - 1));
    const size_t j0 = size_t(clampi(y0, 0, a.h - 1)) * size_t(a.w);
    const size_t j1 = size_t(clampi(y0 + 1, 0, a.h - 1)) * size_t(a.w);
    const float w00 = (1 - ty) * (1 - tx), w01 = (1 - ty) * tx, w10 = ty * (1 - tx), w11 = ty * tx;
    const float vx =
        w00 * a.mx[j0 + i0] + w01 * a.mx[j0 + i1] + w10 * a.mx[j1 + i0] + w11 * a.mx[j1 + i1];
    const float vy =
        w00 * a.my[j0 + i0] + w01 * a.my[j0 + i1] + w10 * a.my[j1 + i0] + w11 * a.my[j1 + i1];
    px += a.f * vx, py += a.f * vy;
    // Off screen, the position is kept (as nsrr.warp_positions does): later steps test it.
    const bool inside = px >= 0 && px < float(a.W) && py >= 0 && py < float(a.H);
    const int32_t j = inside ? a.row_at[floor_int(py)] : -1;
    const int32_t i = inside ? a.col_at[floor_int(px)] : -1;
    out[X] = j < 0 || i < 0 ? -1 : j * a.w + i;
  }
}

namespace {
template <typename T>
void grid_rows(const GridFill& a, T* grid, size_t gy0, size_t gy1) {
  constexpr size_t kC = size_t(GridFill::kChannels), kX = size_t(GridFill::kX);
  const float zero[GridFill::kX] = {0.0f, 0.0f, 0.0f, 0.0f};
  const size_t N = size_t(a.W) * size_t(a.H);
  for (size_t gy = gy0; gy < gy1; ++gy)
    for (size_t r = 0; r < 4; ++r) {
      const size_t Y = 4 * gy + r;
      for (size_t X = 0; X < 4 * size_t(a.Gw); ++X) {
        const size_t cell = (gy * size_t(a.Gw) + X / 4) * kC, sub = r * 4 + X % 4;
        const bool inside = X < size_t(a.W) && Y < size_t(a.H);
        const size_t q = Y * size_t(a.W) + X;
        for (size_t k = 0; k < size_t(GridFill::kFrames); ++k) {
          const int32_t i = inside && k < size_t(a.frames) ? a.at[k][q] : -1;
          const float* x = i < 0 ? zero : a.packed + kX * (k * a.n + size_t(i));
          T* g = grid + cell + kX * k * 16 + sub;
          for (size_t c = 0; c < kX; ++c) store(g[16 * c], x[c]);
        }
        for (size_t c = 0; c < 3; ++c)
          store(grid[cell + size_t(GridFill::kHistory) + 16 * c + sub],
                inside ? a.hist[c * N + q] : 0.0f);
        if (sub == 0) store(grid[cell + kC - 1], a.last);
      }
    }
}
}  // namespace

void grid_rows_scalar(const GridFill& a, size_t gy0, size_t gy1) {
  if (a.bf16)
    grid_rows(a, static_cast<uint16_t*>(a.grid), gy0, gy1);
  else
    grid_rows(a, static_cast<float*>(a.grid), gy0, gy1);
}

GridRowsFn grid_rows_for(Isa isa) {
  return isa == Isa::avx512 ? grid_rows_avx512 : grid_rows_scalar;
}

WarpRowFn warp_row_for(Isa isa) {
  return isa == Isa::avx512 ? warp_row_avx512 : warp_row_scalar;
}

void Window::warp(int f, int W, int H, int previous, std::vector<int32_t>& src) const {
  const int w = frames_.front().w, h = frames_.front().h;
  const size_t n = size_t(w) * size_t(h), N = size_t(W) * size_t(H);
  const size_t available = std::min(frames_.size(), size_t(previous) + 1);
  src.resize(size_t(previous) * N);
  std::fill(src.begin() + std::ptrdiff_t((available - 1) * N), src.end(), -1);
  const WarpRowFn warp_row = warp_row_for(default_isa());
  parallel_for(0, size_t(H), 4, [&](size_t r0, size_t r1) {
    std::vector<float> pos(2 * size_t(W));  // the row's positions, warped frame by frame
    for (size_t Y = r0; Y < r1; ++Y) {
      for (size_t X = 0; X < size_t(W); ++X)
        pos[2 * X] = float(X) + 0.5f, pos[2 * X + 1] = float(Y) + 0.5f;
      for (size_t k = 1; k < available; ++k) {
        const float* m = frames_[k - 1].motion.data();
        const WarpRow a{m, m + n,    frames_[k].col_at(), frames_[k].row_at.data(), w, h, W,
                        H, float(f), 1.0f / float(f)};
        warp_row(a, pos.data(), src.data() + (k - 1) * N + Y * size_t(W));
      }
    }
  });
}

void Member::history_y(const FloatImage& history) {
  const size_t N = size_t(history.width) * size_t(history.height);
  hist.resize(3 * N);
  parallel_for(0, N, 4096, [&](size_t q0, size_t q1) {
    for (size_t q = q0; q < q1; ++q) to_y_planar(history.pixels.data(), q, hist.data(), N);
  });
}

Member::Member(const std::string& weights, int factor, bool bf16, uint32_t architecture,
               const std::vector<nn::LayerSpec>& specs, const char* what)
    : f(factor) {
  layers = nn::load_layers(weights, kMagic, architecture, specs, what);
  for (const nn::ConvLayer& L : layers)
    parameters_ += size_t(L.outputs) * (size_t(L.cin) * size_t(L.ksize * L.ksize) + 1);
  dnn.bf16 = bf16 && Dnn::bf16_available();
}

}  // namespace kestrel::upscale::nsrr
