// Refitting wide BVHs (two passes: block boxes in parallel chunks, then the nodes bottom up)
// and binary ones, after their triangles moved.
#include <algorithm>
#include <cmath>
#include <vector>

#include <fmt/format.h>

#include "core/parallel.h"
#include "core/simd/vec4f.h"
#include "core/vec.h"
#include "kestrel/error.h"
#include "traverse/wide_bvh.h"

namespace kestrel {

namespace {

// Min / max over the four lanes of a 128-bit row.
float hmin(simd::Vec4f v) {
  v = min(v, simd::Vec4f(_mm_shuffle_ps(v.v, v.v, _MM_SHUFFLE(1, 0, 3, 2))));
  v = min(v, simd::Vec4f(_mm_shuffle_ps(v.v, v.v, _MM_SHUFFLE(2, 3, 0, 1))));
  return _mm_cvtss_f32(v.v);
}
float hmax(simd::Vec4f v) {
  v = max(v, simd::Vec4f(_mm_shuffle_ps(v.v, v.v, _MM_SHUFFLE(1, 0, 3, 2))));
  v = max(v, simd::Vec4f(_mm_shuffle_ps(v.v, v.v, _MM_SHUFFLE(2, 3, 0, 1))));
  return _mm_cvtss_f32(v.v);
}

// One leaf block's box and whether it ends its leaf: what the node pass needs, written by the
// block pass so the node pass never goes back to the (cold) blocks.
struct BlockBox {
  float lo[3];
  uint32_t last;
  float hi[3];
  uint32_t pad;
};

// Pass 1, over the blocks in memory order (chunks in parallel): new vertices, then the
// block's box while it is hot. Returns the smallest invalid prim id met, or ~0u.
uint32_t refit_blocks(std::span<TriangleBlock> blocks, std::span<BlockBox> boxes,
                      BlockRewrite rewrite) {
  using simd::Vec4f;
  constexpr size_t grain = 2048;
  const size_t chunks = chunk_count(blocks.size(), grain);
  std::vector<uint32_t> bad(chunks, ~0u);
  parallel_for(0, chunks, 1, [&](size_t c0, size_t c1) {
    for (size_t c = c0; c < c1; ++c) {
      const size_t b0 = c * grain, b1 = std::min(blocks.size(), b0 + grain);
      bad[c] = rewrite(blocks.subspan(b0, b1 - b0));
      for (size_t b = b0; b < b1; ++b) {
        const TriangleBlock& blk = blocks[b];
        BlockBox& out = boxes[b];
        for (int a = 0; a < 3; ++a) {  // one row per vertex and axis: 4 lanes at once
          const Vec4f v0 = Vec4f::load(blk.v[0][a]), v1 = Vec4f::load(blk.v[1][a]),
                      v2 = Vec4f::load(blk.v[2][a]);
          out.lo[a] = hmin(min(min(v0, v1), v2));
          out.hi[a] = hmax(max(max(v0, v1), v2));
        }
        out.last = blk.prim_id[0] & block_last_bit;
      }
    }
  });
  uint32_t first_bad = ~0u;
  for (uint32_t b : bad) first_bad = std::min(first_bad, b);
  return first_bad;
}

double slot_area(float dx, float dy, float dz) {
  return double(dx) * dy + double(dy) * dz + double(dz) * dx;
}

// Pass 2, bottom-up over the nodes (children follow their parent in the array): each slot's
// box from its child node or its leaf's block boxes; the SAH cost on the way.
template <int W, class Wide>
double refit_nodes(Wide& bvh, BlockRewrite rewrite) {
  using simd::Vec4f;
  if (bvh.empty()) return 0;
  Buffer<BlockBox> boxes(bvh.blocks.size());  // every entry written by refit_blocks
  const uint32_t bad = refit_blocks({bvh.blocks.data(), bvh.blocks.size()}, boxes, rewrite);
  if (bad != ~0u)
    throw Error(
        ErrorCode::invalid_argument,
        fmt::format("refit: triangle {} is no longer valid (NaN/Inf vertex or bad index); rebuild",
                    bad));
  const float inf = INFINITY;
  double cost = 0;
  Buffer<BlockBox> node_box(bvh.nodes.size());  // each node's box, written once its slots are set
  constexpr size_t ahead = 4;  // leaf block boxes are gathers: prefetch a few nodes ahead
  for (size_t i = bvh.nodes.size(); i-- > 0;) {
    if (i >= ahead)
      for (const uint32_t ref : bvh.nodes[i - ahead].child)
        if (ref != wide_empty && (ref & wide_leaf_bit))
          __builtin_prefetch(&boxes[ref & ~wide_leaf_bit]);
    auto& node = bvh.nodes[i];
    float nlo[3] = {inf, inf, inf}, nhi[3] = {-inf, -inf, -inf};
    for (int j = 0; j < W; ++j) {
      const uint32_t ref = node.child[j];
      if (ref == wide_empty) continue;
      float lo[3], hi[3];
      double weight = 1;
      const BlockBox* b = ref & wide_leaf_bit ? &boxes[ref & ~wide_leaf_bit] : &node_box[ref];
      for (int a = 0; a < 3; ++a) lo[a] = b->lo[a], hi[a] = b->hi[a];
      if (ref & wide_leaf_bit)
        for (; !b->last; weight += 1) {
          ++b;
          for (int a = 0; a < 3; ++a) {
            lo[a] = std::min(lo[a], b->lo[a]);
            hi[a] = std::max(hi[a], b->hi[a]);
          }
        }
      set_wide_slot(node, j, Bounds3{{lo[0], lo[1], lo[2]}, {hi[0], hi[1], hi[2]}}, ref);
      cost += weight * slot_area(hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]);
      for (int a = 0; a < 3; ++a) {
        nlo[a] = std::min(nlo[a], lo[a]);
        nhi[a] = std::max(nhi[a], hi[a]);
      }
    }
    BlockBox& nb = node_box[i];
    for (int a = 0; a < 3; ++a) nb.lo[a] = nlo[a], nb.hi[a] = nhi[a];
  }
  const Bounds3 box = wide_bounds(bvh);
  const double root = slot_area(box.hi.x - box.lo.x, box.hi.y - box.lo.y, box.hi.z - box.lo.z);
  return root > 0 ? 1.0 + cost / root : 1.0;
}

}  // namespace

double refit_wide(Bvh4& bvh, BlockRewrite rewrite) {
  return refit_nodes<4>(bvh, rewrite);
}
double refit_wide(Bvh8& bvh, BlockRewrite rewrite) {
  return refit_nodes<8>(bvh, rewrite);
}
void refit_bvh2(Bvh2& bvh, std::span<const Triangle> tris) {
  if (bvh.empty()) return;
  // Parents before children (breadth first), then boxes in reverse.
  std::vector<uint32_t> order{0};
  for (size_t i = 0; i < order.size(); ++i) {
    const Bvh2Node& n = bvh.nodes[order[i]];
    if (!n.is_leaf()) {
      order.push_back(n.index);
      order.push_back(n.index + 1);
    }
  }
  for (size_t i = order.size(); i-- > 0;) {
    Bvh2Node& n = bvh.nodes[order[i]];
    Bounds3 box;
    if (n.is_leaf()) {
      for (uint32_t k = n.index; k < n.index + n.count; ++k) {
        extend(box, tris[k].v0);
        extend(box, tris[k].v1);
        extend(box, tris[k].v2);
      }
    } else {
      for (uint32_t c = n.index; c < n.index + 2; ++c) {
        extend(box, bvh.nodes[c].lo);
        extend(box, bvh.nodes[c].hi);
      }
    }
    n.lo = box.lo;
    n.hi = box.hi;
  }
}

}  // namespace kestrel
