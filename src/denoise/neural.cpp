// The neural denoiser: weights file and the per-frame network (model.py's function).
#include "denoise/neural.h"

#include <fmt/format.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstring>

#include "core/file_io.h"
#include "denoise/kernels.h"
#include "kestrel/error.h"

namespace kestrel::denoise {

namespace {
constexpr char kMagic[9] = "KSTRLDNW";
constexpr uint32_t kArchitecture = 4;  // 4: firefly cut, accumulated history (model.py)
}  // namespace

size_t next_planes_offset() {
  static std::atomic<unsigned> count{0};
  return (count.fetch_add(1, std::memory_order_relaxed) * 23u) % 64u;  // 23: odd, far from 37
}

NeuralWeights NeuralWeights::load(const std::string& path) {
  std::vector<ConvLayer> l = load_layers(path, kMagic, kArchitecture,
                                         {{"enc1", 16, kFeatures, 3},
                                          {"enc2", 32, 16, 3},
                                          {"enc3", 32, 32, 3},
                                          {"dec1", 16, 48, 3},
                                          {"head", kOutputs, 16, 1}},
                                         "denoiser");
  NeuralWeights w;
  w.enc1 = std::move(l[0]), w.enc2 = std::move(l[1]), w.enc3 = std::move(l[2]),
  w.dec1 = std::move(l[3]), w.head = std::move(l[4]);
  for (const ConvLayer* c : {&w.enc1, &w.enc2, &w.enc3, &w.dec1, &w.head})
    w.parameters += size_t(c->outputs) * (size_t(c->cin) * size_t(c->ksize * c->ksize) + 1);
  return w;
}

const Planes& run_network(const NeuralWeights& w, const Planes& in, Planes& state, bool recurrent,
                          Workspace& ws, StageTimes* times) {
  return host_kernels().network(w, in, state, recurrent, ws, times);
}

}  // namespace kestrel::denoise
