#include "traverse/stream.h"

#include <algorithm>
#include <cmath>

#include "bvh/morton.h"
#include "bvh/radix_sort.h"
#include "core/parallel.h"

namespace kestrel {

namespace {
constexpr int index_bits = 20, key_bits = 40;
static_assert(stream_group <= size_t(1) << index_bits);

// Cell of (v - lo) * scale in [0, 2^bits); NaN and values outside clamp to the range.
inline uint32_t cell(float v, float lo, float scale, uint32_t last) {
  const float t = (v - lo) * scale;
  if (!(t > 0.0f)) return 0;
  return t >= float(last) ? last : uint32_t(t);
}

struct KeyMaker {
  explicit KeyMaker(const Bounds3& box) : lo{box.lo.x, box.lo.y, box.lo.z} {
    const float hi[3] = {box.hi.x, box.hi.y, box.hi.z};
    for (int a = 0; a < 3; ++a)
      scale[a] = hi[a] > lo[a] && std::isfinite(hi[a] - lo[a]) ? 512.0f / (hi[a] - lo[a]) : 0.0f;
  }
  // Octant (3 bits), origin at 5 bits per axis (Morton), direction (5 + 5 bits of the
  // octahedral |x|, |y|), then the origin's next 4 bits per axis (Morton): 40 bits.
  uint64_t operator()(const Ray& r) const {
    const uint32_t m =
        morton30(cell(r.org.x, lo[0], scale[0], 511), cell(r.org.y, lo[1], scale[1], 511),
                 cell(r.org.z, lo[2], scale[2], 511));
    const uint32_t octant = uint32_t(std::signbit(r.dir.x)) | uint32_t(std::signbit(r.dir.y)) << 1 |
                            uint32_t(std::signbit(r.dir.z)) << 2;
    const float ax = std::fabs(r.dir.x), ay = std::fabs(r.dir.y), az = std::fabs(r.dir.z);
    const float l = ax + ay + az, inv = l > 0 ? 32.0f / l : 0.0f;
    const uint32_t u = cell(ax, 0.0f, inv, 31), v = cell(ay, 0.0f, inv, 31);
    return uint64_t(octant) << 37 | uint64_t(m >> 12) << 22 | u << 17 | v << 12 | (m & 0xFFF);
  }
  float lo[3], scale[3];
};
}  // namespace

void stream_order(std::span<const Ray> rays, const Bounds3& box, RawArray<uint32_t>& order,
                  RawArray<uint64_t>& scratch) {
  const size_t n = rays.size();
  if (scratch.size() < 2 * n) scratch.resize(2 * n);
  uint64_t* a = scratch.data();
  uint64_t* b = scratch.data() + n;
  const KeyMaker key(box);
  parallel_for(0, n, 8192, [&](size_t i0, size_t i1) {
    for (size_t i = i0; i < i1; ++i) a[i] = key(rays[i]) << index_bits | i;
  });
  a = radix_sort_packed_parallel(a, b, n, index_bits, key_bits);
  order.resize(n);
  parallel_for(0, n, 16384, [&](size_t i0, size_t i1) {
    for (size_t i = i0; i < i1; ++i) order[i] = uint32_t(a[i] & ((1u << index_bits) - 1));
  });
}

namespace {
int dominant_axis(const Vec3& d) {
  const float ax = std::fabs(d.x), ay = std::fabs(d.y), az = std::fabs(d.z);
  return ax >= ay ? (ax >= az ? 0 : 2) : (ay >= az ? 1 : 2);
}

// Whether consecutive rays start far apart: sampled neighbour pairs whose origins are more
// than 1/64 of the scene's diagonal apart, in the majority. A renderer's bounces in pixel
// order start close to each other; rays compacted, sorted by material or shuffled do not.
bool origins_unordered(std::span<const Ray> rays, const Bounds3& box) {
  const Vec3 d = box.hi - box.lo;
  const float near2 = (d.x * d.x + d.y * d.y + d.z * d.z) / (64.0f * 64.0f);
  const size_t step = std::max<size_t>(1, rays.size() / 4096);
  size_t pairs = 0, far = 0;
  for (size_t i = 0; i + 1 < rays.size(); i += step) {
    const Vec3 e = rays[i + 1].org - rays[i].org;
    ++pairs;
    far += !(e.x * e.x + e.y * e.y + e.z * e.z <= near2);  // NaN counts as far
  }
  return 2 * far > pairs;
}
}  // namespace

// Coherent rays trace faster as packets: camera rays, and shadow rays from neighbouring
// points towards one light. The default samples each chunk: a group of 8 consecutive rays
// counts as coherent when its directions agree in sign on every axis and in their dominant
// axis (random bounce directions almost never do); packets are used when 3 groups in 4 are.
bool looks_coherent(std::span<const Ray> rays) {
  size_t groups = 0, coherent = 0;
  // A group every 64 rays, at most coherent_samples groups spread over the batch: the groups
  // of a large batch are far apart in memory, so each one read is a cache miss (reading one in
  // 64 of 921 600 camera rays cost ~3 % of tracing them as packets).
  const size_t stride = std::max<size_t>(64, rays.size() / coherent_samples / 8 * 8);
  for (size_t g = 0; g + 8 <= rays.size(); g += stride) {
    ++groups;
    const Ray& a = rays[g];
    const int axis = dominant_axis(a.dir);
    bool same = true;
    for (size_t k = 1; k < 8 && same; ++k) {
      const Ray& b = rays[g + k];
      same = std::signbit(b.dir.x) == std::signbit(a.dir.x) &&
             std::signbit(b.dir.y) == std::signbit(a.dir.y) &&
             std::signbit(b.dir.z) == std::signbit(a.dir.z) && dominant_axis(b.dir) == axis;
    }
    coherent += same;
  }
  return groups > 0 && coherent * 4 >= groups * 3;
}

// Measured in docs/benchmarks.md. Unordered (shuffled, compacted, material-sorted) batches
// gain from the order and, where the kernels have them, from ray streams over any tree (one
// thread, 720p: shuffled diffuse rays 1.13-1.77x `rtcIntersect1` as ray streams on the five
// scenes with >= 2^18 of them); sorted packets pay only over trees larger than the caches.
// Batches in pixel order gain from ray streams on some scenes (Sponza's 908 k bounces 3.9 ->
// 5.9 Mrays/s) and lose on others (the terrain's 543 k 5.9 -> 4.4): trace.cpp times those each
// way (may_stream). Any hit never takes it by default.
bool stream_by_default(std::span<const Ray> rays, const Bounds3& box, size_t tree_bytes,
                       bool any_hit, bool ray_streams, const TraceOptions& options) {
  if (options.stream) return *options.stream;
  if (any_hit || options.packets || rays.size() < stream_min_rays || looks_coherent(rays))
    return false;
  return (ray_streams || tree_bytes >= stream_min_accel_bytes) && origins_unordered(rays, box);
}

void for_each_stream_chunk(
    std::span<const Ray> rays, const Bounds3& box,
    FunctionRef<void(const Ray* rays, const uint32_t* callers, size_t n)> chunk,
    size_t chunk_rays) {
  RawArray<uint32_t> order;
  RawArray<uint64_t> scratch;
  for (size_t g0 = 0; g0 < rays.size(); g0 += stream_group) {
    const auto group = rays.subspan(g0, std::min(stream_group, rays.size() - g0));
    stream_order(group, box, order, scratch);
    parallel_for(0, group.size(), std::max<size_t>(1024, chunk_rays), [&](size_t b, size_t e) {
      constexpr size_t ahead = 16;  // the gather is random: prefetched
      RawArray<Ray> sorted(std::min(chunk_rays, e - b));
      RawArray<uint32_t> callers(sorted.size());
      for (size_t i = b; i < e; i += chunk_rays) {
        const size_t n = std::min(chunk_rays, e - i);
        for (size_t j = 0; j < n; ++j) {
          if (i + j + ahead < e) __builtin_prefetch(&group[order[i + j + ahead]]);
          sorted[j] = group[order[i + j]];
          callers[j] = uint32_t(g0 + order[i + j]);
        }
        chunk(sorted.data(), callers.data(), n);
      }
    });
  }
}

}  // namespace kestrel
