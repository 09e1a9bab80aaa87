#include "scene/instance_tree.h"

#include <algorithm>
#include <cmath>

#include "bvh/morton.h"
#include "bvh/radix_sort.h"
#include "core/raw_array.h"

namespace kestrel {

namespace {

template <int W, class Node>
struct TreeBuilder {
  const PrimRef* refs;  // in Morton order
  const uint32_t* keys;
  Buffer<Node>& nodes;

  uint32_t split(uint32_t b, uint32_t e) const { return morton_split(keys, b, e); }

  // Fills node `index` over sorted positions [b, e) (e - b >= 2) and returns its bounds.
  Bounds3 build(uint32_t index, uint32_t b, uint32_t e) {
    uint32_t lo[W], hi[W];
    int parts = 1;
    lo[0] = b, hi[0] = e;
    while (parts < W) {
      int big = -1;
      uint32_t big_size = 1;
      for (int i = 0; i < parts; ++i)
        if (hi[i] - lo[i] > big_size) big = i, big_size = hi[i] - lo[i];
      if (big < 0) break;
      const uint32_t m = split(lo[big], hi[big]);
      lo[parts] = m, hi[parts] = hi[big];
      hi[big] = m;
      ++parts;
    }
    Node node;
    Bounds3 total;
    for (int j = 0; j < W; ++j) {
      Bounds3 box;
      uint32_t ref = wide_empty;
      if (j < parts) {
        if (hi[j] - lo[j] == 1) {
          const PrimRef& r = refs[lo[j]];
          box = {r.lo, r.hi};
          ref = wide_leaf_bit | r.prim_id;
        } else {
          ref = uint32_t(nodes.size());
          nodes.emplace_back();
          box = build(ref, lo[j], hi[j]);
        }
        total.lo = {std::min(total.lo.x, box.lo.x), std::min(total.lo.y, box.lo.y),
                    std::min(total.lo.z, box.lo.z)};
        total.hi = {std::max(total.hi.x, box.hi.x), std::max(total.hi.y, box.hi.y),
                    std::max(total.hi.z, box.hi.z)};
      } else {
        const float inf = INFINITY;
        box = {{inf, inf, inf}, {-inf, -inf, -inf}};
      }
      node.bounds[0][j] = box.lo.x, node.bounds[1][j] = box.hi.x;
      node.bounds[2][j] = box.lo.y, node.bounds[3][j] = box.hi.y;
      node.bounds[4][j] = box.lo.z, node.bounds[5][j] = box.hi.z;
      node.child[j] = ref;
    }
    nodes[index] = node;
    return total;
  }
};

template <int W, class Node>
void build(std::span<const PrimRef> refs, const Bounds3& cb, Buffer<Node>& nodes,
           InstanceTreeScratch& scratch) {
  nodes.clear();
  const size_t n = refs.size();
  if (n == 0) return;
  const float cells = 1024.0f, top = 1023.0f;
  const Vec3 ext{cb.hi.x - cb.lo.x, cb.hi.y - cb.lo.y, cb.hi.z - cb.lo.z};
  const Vec3 scale{ext.x > 0 ? cells / ext.x : 0.0f, ext.y > 0 ? cells / ext.y : 0.0f,
                   ext.z > 0 ? cells / ext.z : 0.0f};
  RawArray<uint64_t>& records = scratch.records;
  RawArray<uint32_t>& keys = scratch.keys;
  if (records.size() != n) records.resize(n), scratch.tmp.resize(n), keys.resize(n);
  // v > 0 ? v : 0, not clamp: an instance whose world box overflowed to inf has a NaN
  // centre, which this maps to 0 (converting NaN to an integer is undefined). (Not
  // std::fmax: without -ffast-math GCC calls libm for it.)
  auto cell = [top](float v) {
    v = v > 0.0f ? v : 0.0f;
    return uint32_t(v < top ? v : top);
  };
  for (size_t i = 0; i < n; ++i) {
    const PrimRef& r = refs[i];
    const uint32_t code = morton30(cell((r.lo.x + r.hi.x - cb.lo.x) * scale.x),
                                   cell((r.lo.y + r.hi.y - cb.lo.y) * scale.y),
                                   cell((r.lo.z + r.hi.z - cb.lo.z) * scale.z));
    records[i] = uint64_t(code) << 32 | i;
  }
  // Stable on the codes (bits 32-61), so equal codes keep the refs' order. Serial, into
  // buffers kept between builds: no fresh pages, no pack / unpack passes.
  const uint64_t* order = radix_sort_packed(records.data(), scratch.tmp.data(), n, 32, 30);
  // The refs in Morton order, gathered once in a prefetched loop (the tree build then reads
  // them sequentially instead of at random).
  Buffer<PrimRef>& sorted = scratch.sorted;
  sorted.resize(n);
  for (size_t i = 0; i < n; ++i) {
    if (i + 16 < n) __builtin_prefetch(&refs[uint32_t(order[i + 16])]);
    sorted[i] = refs[uint32_t(order[i])];
    keys[i] = uint32_t(order[i] >> 32);
  }
  nodes.reserve(n / (W - 1) + 2);
  nodes.emplace_back();
  TreeBuilder<W, Node> tb{sorted.data(), &keys[0], nodes};
  if (n == 1) {
    // One instance: the root holds one leaf slot.
    Node node;
    const float inf = INFINITY;
    for (int j = 0; j < W; ++j) {
      const bool used = j == 0;
      node.bounds[0][j] = used ? refs[0].lo.x : inf, node.bounds[1][j] = used ? refs[0].hi.x : -inf;
      node.bounds[2][j] = used ? refs[0].lo.y : inf, node.bounds[3][j] = used ? refs[0].hi.y : -inf;
      node.bounds[4][j] = used ? refs[0].lo.z : inf, node.bounds[5][j] = used ? refs[0].hi.z : -inf;
      node.child[j] = used ? (wide_leaf_bit | refs[0].prim_id) : wide_empty;
    }
    nodes[0] = node;
    return;
  }
  tb.build(0, 0, uint32_t(n));
}

}  // namespace

void build_instance_tree(std::span<const PrimRef> refs, const Bounds3& centres,
                         Buffer<Bvh4Node>& nodes, InstanceTreeScratch& scratch) {
  build<4, Bvh4Node>(refs, centres, nodes, scratch);
}
void build_instance_tree(std::span<const PrimRef> refs, const Bounds3& centres,
                         Buffer<Bvh8Node>& nodes, InstanceTreeScratch& scratch) {
  build<8, Bvh8Node>(refs, centres, nodes, scratch);
}

}  // namespace kestrel
