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
  fr.y.resize(3 * n), fr.depth.resize(n), fr.motion.resize(2 * n), fr.sample_at.assign(N, -1);
  const int mc = in.motion ? in.motion->channels : 0;
  // Per row: the depth sum and count (summed in row order after: the same at any thread count).
  std::vector<double> row_sum(static_cast<size_t>(h));
  std::vector<size_t> row_count(static_cast<size_t>(h));
  parallel_for(0, size_t(h), 4, [&](size_t j0, size_t j1) {
    for (size_t j = j0; j < j1; ++j) {
      double sum = 0;
      size_t count = 0;
      for (size_t p = j * size_t(w); p < (j + 1) * size_t(w); ++p) {
        float c[3];
        for (size_t k = 0; k < 3; ++k)
          c[k] = std::max(finite_or_zero(in.color->pixels[3 * p + k]), 0.0f);
        const float s = 1.0f / (1.0f + luma(c));
        for (size_t k = 0; k < 3; ++k) fr.y[k * n + p] = c[k] * s;
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
  // zero_upsample: the sample of low-res pixel (i, j) lands in the output pixel containing it
  // (serial: with a jitter outside [0, 1) clamped samples share a pixel, the last one kept).
  for (int j = 0; j < h; ++j)
    for (int i = 0; i < w; ++i) {
      const int X = clampi(floor_int(float(f) * (float(i) + fr.jx)), 0, W - 1);
      const int Y = clampi(floor_int(float(f) * (float(j) + fr.jy)), 0, H - 1);
      fr.sample_at[size_t(Y) * size_t(W) + size_t(X)] = j * w + i;
    }
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
    out[X] = inside ? a.at[size_t(floor_int(py)) * size_t(a.W) + size_t(floor_int(px))] : -1;
  }
}

namespace {
template <typename T>
void grid_rows(const GridFill& a, T* grid, size_t gy0, size_t gy1) {
  constexpr size_t kC = size_t(GridFill::kChannels), kX = size_t(GridFill::kX);
  const float zero[GridFill::kX] = {0.0f, 0.0f, 0.0f, 0.0f};
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
        const WarpRow a{m,        m + n,          frames_[k].sample_at.data(), w, h, W, H,
                        float(f), 1.0f / float(f)};
        warp_row(a, pos.data(), src.data() + (k - 1) * N + Y * size_t(W));
      }
    }
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

bool Dnn::bf16_available() {
  return dnnl::get_effective_cpu_isa() >= dnnl::cpu_isa::avx512_core_bf16;
}

memory Dnn::weights_of(const nn::ConvLayer& L, const memory::desc& want) {
  // ConvLayer: [ky][kx][cin][cout stride] -> oihw.
  const int co = L.outputs, ci = L.cin, k = L.ksize, taps = k * k;
  memory plain({{co, ci, k, k}, dt::f32, tag::oihw}, eng);
  float* p = static_cast<float*>(plain.get_data_handle());
  for (int o = 0; o < co; ++o)
    for (int i = 0; i < ci; ++i)
      for (int t = 0; t < taps; ++t)
        p[(size_t(o) * size_t(ci) + size_t(i)) * size_t(taps) + size_t(t)] =
            L.weights[(size_t(t) * size_t(ci) + size_t(i)) * size_t(L.cout) + size_t(o)];
  memory out(want, eng);
  dnnl::reorder(plain, out).execute(strm, plain, out);
  return out;
}

memory Dnn::conv(Net& net, memory in, const nn::ConvLayer& L, bool relu, bool last,
                 const dnnl::post_ops* extra, tag last_tag) {
  const memory::dims d = in.get_desc().dims();
  const memory::dim pad = L.ksize / 2;
  const memory::desc src_any({d[0], L.cin, d[2], d[3]}, act(), tag::any);
  // The last layer's output is read by this code in last_tag's layout; the convolution still
  // writes the layout it prefers, then a reorder (fixing its destination layout to nhwc made
  // oneDNN fall back to its reference convolution on AVX2: 0.3 s per 1x1 layer at 320 x 180).
  const memory::desc dst_any({d[0], L.outputs, d[2], d[3]}, last ? dt::f32 : act(), tag::any);
  const memory::desc wei_any({L.outputs, L.cin, L.ksize, L.ksize}, act(), tag::any);
  const memory::desc bias_md({L.outputs}, dt::f32, tag::x);
  dnnl::convolution_forward::desc cd(dnnl::prop_kind::forward_inference,
                                     dnnl::algorithm::convolution_direct, src_any, wei_any, bias_md,
                                     dst_any, {1, 1}, {pad, pad}, {pad, pad});
  dnnl::post_ops po = extra ? *extra : dnnl::post_ops();
  if (relu) po.append_eltwise(1.0f, dnnl::algorithm::eltwise_relu, 0.0f, 0.0f);
  dnnl::primitive_attr attr;
  attr.set_post_ops(po);
  dnnl::convolution_forward::primitive_desc pd(cd, attr, eng);
  if (pd.src_desc() != in.get_desc()) {
    memory r(pd.src_desc(), eng);
    net.steps.push_back({dnnl::reorder(in, r), {{DNNL_ARG_FROM, in}, {DNNL_ARG_TO, r}}});
    in = r;
  }
  memory bias(bias_md, eng);
  std::copy(L.bias.begin(), L.bias.begin() + L.outputs,
            static_cast<float*>(bias.get_data_handle()));
  memory dst(pd.dst_desc(), eng);
  net.steps.push_back({dnnl::convolution_forward(pd),
                       {{DNNL_ARG_SRC, in},
                        {DNNL_ARG_WEIGHTS, weights_of(L, pd.weights_desc())},
                        {DNNL_ARG_BIAS, bias},
                        {DNNL_ARG_DST, dst}}});
  if (!last) return dst;
  const memory::desc want({d[0], L.outputs, d[2], d[3]}, dt::f32, last_tag);
  if (pd.dst_desc() == want) return dst;
  memory plain(want, eng);
  net.steps.push_back({dnnl::reorder(dst, plain), {{DNNL_ARG_FROM, dst}, {DNNL_ARG_TO, plain}}});
  return plain;
}

memory Dnn::pool(Net& net, memory in) {
  const memory::desc d = in.get_desc();
  const memory::dims s = d.dims();
  const memory::desc out_any({s[0], s[1], s[2] / 2, s[3] / 2}, act(), tag::any);
  dnnl::pooling_forward::primitive_desc pd({dnnl::prop_kind::forward_inference,
                                            dnnl::algorithm::pooling_max,
                                            d,
                                            out_any,
                                            {2, 2},
                                            {2, 2},
                                            {0, 0},
                                            {0, 0}},
                                           eng);
  memory out(pd.dst_desc(), eng);
  net.steps.push_back({dnnl::pooling_forward(pd), {{DNNL_ARG_SRC, in}, {DNNL_ARG_DST, out}}});
  return out;
}

memory Dnn::up_concat(Net& net, memory low, memory skip) {
  const memory::desc d = low.get_desc();
  const memory::dims s = skip.get_desc().dims();
  const memory::desc up_md({d.dims()[0], d.dims()[1], s[2], s[3]}, act(), tag::any);
  dnnl::resampling_forward::primitive_desc pd(
      {dnnl::prop_kind::forward_inference, dnnl::algorithm::resampling_linear, d, up_md}, eng);
  memory up(pd.dst_desc(), eng);
  net.steps.push_back({dnnl::resampling_forward(pd), {{DNNL_ARG_SRC, low}, {DNNL_ARG_DST, up}}});
  dnnl::concat::primitive_desc cpd(1, {up.get_desc(), skip.get_desc()}, eng);
  memory cat(cpd.dst_desc(), eng);
  net.steps.push_back(
      {dnnl::concat(cpd),
       {{DNNL_ARG_MULTIPLE_SRC, up}, {DNNL_ARG_MULTIPLE_SRC + 1, skip}, {DNNL_ARG_DST, cat}}});
  return cat;
}

}  // namespace kestrel::upscale::nsrr
