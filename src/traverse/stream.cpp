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
  a = radix_sort_packed(a, b, n, index_bits, key_bits);
  order.resize(n);
  for (size_t i = 0; i < n; ++i) order[i] = uint32_t(a[i] & ((1u << index_bits) - 1));
}

}  // namespace kestrel
