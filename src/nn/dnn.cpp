// oneDNN networks (dnn.h).
#include "nn/dnn.h"

namespace kestrel::nn {

using dnnl::memory;
using tag = memory::format_tag;
using dt = memory::data_type;

bool Dnn::bf16_available() {
  return dnnl::get_effective_cpu_isa() >= dnnl::cpu_isa::avx512_core_bf16;
}

memory Dnn::weights_of(const ConvLayer& L, const memory::desc& want) {
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

memory Dnn::conv(Net& net, memory in, const ConvLayer& L, bool relu, bool last,
                 const dnnl::post_ops* extra, tag last_tag, float slope) {
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
  if (relu) po.append_eltwise(1.0f, dnnl::algorithm::eltwise_relu, slope, 0.0f);
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

memory Dnn::up_concat(Net& net, memory low, memory skip, bool nearest) {
  const memory::desc d = low.get_desc();
  const memory::dims s = skip.get_desc().dims();
  const memory::desc up_md({d.dims()[0], d.dims()[1], s[2], s[3]}, act(), tag::any);
  dnnl::resampling_forward::primitive_desc pd(
      {dnnl::prop_kind::forward_inference,
       nearest ? dnnl::algorithm::resampling_nearest : dnnl::algorithm::resampling_linear, d,
       up_md},
      eng);
  memory up(pd.dst_desc(), eng);
  net.steps.push_back({dnnl::resampling_forward(pd), {{DNNL_ARG_SRC, low}, {DNNL_ARG_DST, up}}});
  return concat(net, up, skip);
}

memory Dnn::concat(Net& net, memory a, memory b) {
  dnnl::concat::primitive_desc pd(1, {a.get_desc(), b.get_desc()}, eng);
  memory cat(pd.dst_desc(), eng);
  net.steps.push_back(
      {dnnl::concat(pd),
       {{DNNL_ARG_MULTIPLE_SRC, a}, {DNNL_ARG_MULTIPLE_SRC + 1, b}, {DNNL_ARG_DST, cat}}});
  return cat;
}

void Dnn::copy(Net& net, memory from, memory to) {
  net.steps.push_back({dnnl::reorder(from, to), {{DNNL_ARG_FROM, from}, {DNNL_ARG_TO, to}}});
}

}  // namespace kestrel::nn
