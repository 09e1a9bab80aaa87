// Spatial-split SAH (Stich, Friedrich & Dietrich 2009, "Spatial splits in bounding volume
// hierarchies"), binned as in their paper: at every node the best object split (binned SAH
// over centroids) competes with the best spatial split (the node's box cut into slabs; each
// reference clipped into every slab it crosses, so a child's box holds only the part of a
// triangle on its side). A primitive cut by the chosen plane goes to both children with the
// bounds of its part there, or whole to one side when that is cheaper ("reference
// unsplitting"). Spatial splits are tried only where the object split's children overlap
// by more than alpha of the root's area, and the extra references a subtree may create are
// a fixed share of a budget handed down in proportion to the children's sizes, so the result
// does not depend on the thread count and the build always ends.
//
// Without triangles (build_bvh over references alone) the reference boxes themselves are
// cut: still a valid tree, but only triangles give the tight boxes the method is for.
#include <algorithm>
#include <cmath>
#include <limits>
#include <utility>
#include <vector>

#include "bvh/builders.h"
#include "bvh/reference_clipper.h"
#include "bvh/sah.h"
#include "core/parallel.h"
#include "core/simd/vec4f.h"
#include "core/vec.h"

namespace kestrel {

namespace {

using simd::Vec4f;

constexpr int object_bins = 32;
constexpr int spatial_bins = 16;
// Ranges at least this large refine their binned object split exactly (as the binned
// builder does): bin boundaries cut through rows of regular meshes.
constexpr size_t refine_min = 256;
// Spatial splits are tried where the object split's children overlap by more than this
// fraction of the root's area (Stich et al.'s alpha; 1e-5 is their recommendation).
constexpr float overlap_alpha = 1e-5f;
// Extra references the whole build may create, as a fraction of the input's.
constexpr float split_budget = 0.5f;
// Subtrees of fewer references are finished by the binned builder (in place, no spatial
// splits): on Sponza and the Lamborghini spatial splits below 256 references lowered the SAH
// cost by 1-2 % and left the trace speed unchanged (within 3 %, four runs), at 1.5-1.8 x the
// build time.
constexpr size_t spatial_min = 256;
// Nodes of at least this many references are binned in parallel, in chunks of binning_chunk.
constexpr size_t parallel_binning_min = size_t(1) << 15;
constexpr size_t binning_chunk = size_t(1) << 13;
// No spatial splits below this depth (a guard: the budget already bounds the work).
constexpr uint32_t max_split_depth = 48;

struct Box {
  Vec4f lo = Vec4f(std::numeric_limits<float>::infinity());
  Vec4f hi = Vec4f(-std::numeric_limits<float>::infinity());
  void add(const PrimRef& r) {
    lo = min(lo, Vec4f::load(&r.lo));
    hi = max(hi, Vec4f::load(&r.hi));
  }
  void add(const Box& b) {
    lo = min(lo, b.lo);
    hi = max(hi, b.hi);
  }
  float area() const { return lo[0] <= hi[0] ? simd::half_area(lo, hi) : 0.0f; }
  float lo_at(int a) const { return lo[a]; }
  float hi_at(int a) const { return hi[a]; }
};

Box box_of(const PrimRef& r) {
  Box b;
  b.add(r);
  return b;
}

float overlap_area(const Box& a, const Box& b) {
  const Vec4f lo = max(a.lo, b.lo), hi = min(a.hi, b.hi);
  for (int k = 0; k < 3; ++k)
    if (!(lo[k] <= hi[k])) return 0.0f;
  return simd::half_area(lo, hi);
}

/// One axis's bins: boxes, references entering (starting in) and leaving (ending in) each;
/// object splits count each reference once, in `entries`.
template <int N>
struct AxisBins {
  Box box[N];
  uint32_t entries[N] = {}, exits[N] = {};
  void merge(const AxisBins& o) {
    for (int i = 0; i < N; ++i) {
      box[i].add(o.box[i]);
      entries[i] += o.entries[i];
      exits[i] += o.exits[i];
    }
  }
};

// Bins the references [0, n) with bin_range(bins, begin, end): in fixed chunks, in parallel,
// for large nodes. Boxes merge by min / max and counts by sums, both exact, so the bins do not
// depend on the thread count.
template <class Bins, class BinRange>
Bins bin_chunks(size_t n, const BinRange& bin_range) {
  Bins out;
  if (n < parallel_binning_min) {
    bin_range(out, 0, n);
    return out;
  }
  const size_t chunks = chunk_count(n, binning_chunk);
  std::vector<Bins> part(chunks);
  parallel_for(0, chunks, 1, [&](size_t cb, size_t ce) {
    for (size_t c = cb; c < ce; ++c)
      bin_range(part[c], c * binning_chunk, std::min(n, (c + 1) * binning_chunk));
  });
  for (const Bins& p : part) out.merge(p);
  return out;
}

/// A node's references and bounds, and the extra references its subtree may create.
struct Work {
  std::vector<PrimRef> refs;
  Box geom, cent;  // cent: of the doubled centroids (lo + hi)
  size_t budget = 0;
  uint32_t depth = 0;

  void add(const PrimRef& r) {
    refs.push_back(r);
    geom.add(r);
    const Vec4f c = simd::clear_w(Vec4f::load(&r.lo)) + Vec4f::load(&r.hi);  // lane 3: prim id
    cent.lo = min(cent.lo, c);
    cent.hi = max(cent.hi, c);
  }
};

/// A subtree under construction: nodes[0] its root, leaves index `ids`.
struct Tree {
  std::vector<Bvh2Node> nodes;
  std::vector<uint32_t> ids;
};

/// The best split found at a node.
struct Split {
  enum Kind { none, object_binned, object_refined, spatial } kind = none;
  int axis = 0;
  int index = 0;  // bin boundary
  float cost = std::numeric_limits<float>::infinity();
  Box left, right;  // the children's boxes as the cost saw them
  size_t left_count = 0, right_count = 0;
  // refined: the boundary bins' references in sorted order, and how many of them go left
  std::vector<uint32_t> middle;
  size_t middle_left = 0;
};

float centroid(const PrimRef& r, int axis) {
  return at(r.lo, axis) + at(r.hi, axis);
}

/// A node's centroid bins on one axis (object splits), its mapping computed once.
struct CentroidBins {
  int axis;
  float lo, scale;
  CentroidBins(const Work& w, int a)
      : axis(a),
        lo(w.cent.lo_at(a)),
        scale(float(object_bins) * 0.99999f / (w.cent.hi_at(a) - w.cent.lo_at(a))) {}
  int operator()(const PrimRef& r) const {
    return std::clamp(int((centroid(r, axis) - lo) * scale), 0, object_bins - 1);
  }
};

class SpatialBuilder {
 public:
  SpatialBuilder(const BuildConfig& config, ReferenceClipper splitter, size_t block_leaf,
                 float root_area)
      : config_(config),
        split_(splitter),
        block_leaf_(block_leaf),
        min_overlap_(overlap_alpha * root_area) {}

  void build(Tree& out, uint32_t slot, Work& w) {
    const size_t n = w.refs.size();
    if (n == 1 || n <= block_leaf_) return make_leaf(out, slot, w);
    if (n < spatial_min) return build_binned(out, slot, w);
    const float inv_area = inverse_area(w.geom.area());
    const Split object = object_split(w, inv_area);
    Split best = object;
    if (w.budget > 0 && w.depth < max_split_depth && object.kind != Split::none &&
        overlap_area(object.left, object.right) > min_overlap_) {
      spatial_split(w, inv_area, best);
    }
    if (n <= config_.max_leaf_size && leaf_cost(config_, n) <= best.cost)
      return make_leaf(out, slot, w);
    Work left, right;
    size_t created = 0;
    if (best.kind == Split::spatial) {
      created = partition_spatial(w, best, left, right);
      if (left.refs.empty() || right.refs.empty()) {  // every part on one side: rare
        left = Work{};
        right = Work{};
        created = 0;
        best = object;
      }
    }
    if (best.kind != Split::spatial) partition_object(w, best, left, right);
    left.depth = right.depth = w.depth + 1;
    // The budget left after this split, shared in proportion to the children's sizes.
    const size_t rest = w.budget - std::min(w.budget, created);
    const size_t nl = left.refs.size(), nr = right.refs.size();
    left.budget = size_t(double(rest) * double(nl) / double(nl + nr));
    right.budget = rest - left.budget;
    std::vector<PrimRef>().swap(w.refs);

    const uint32_t pair = uint32_t(out.nodes.size());
    out.nodes.resize(out.nodes.size() + 2);
    set_inner(out.nodes[slot], w.geom, pair);
    if (n > config_.parallel_threshold) {
      // Each side into a tree of its own (whatever the thread count, so the layout is the
      // same), spliced after the pair in left-right order.
      Tree lt, rt;
      lt.nodes.resize(1);
      rt.nodes.resize(1);
      parallel_invoke([&] { build(lt, 0, left); }, [&] { build(rt, 0, right); });
      splice(out, pair, lt);
      splice(out, pair + 1, rt);
    } else {
      build(out, pair, left);
      build(out, pair + 1, right);
    }
  }

 private:
  static void set_inner(Bvh2Node& node, const Box& b, uint32_t pair) {
    node = Bvh2Node{{b.lo[0], b.lo[1], b.lo[2]}, pair, {b.hi[0], b.hi[1], b.hi[2]}, 0};
  }

  // Below spatial_min the binned builder finishes the subtree (in place, faster); parts of one
  // triangle that meet in one of its leaves are merged there.
  void build_binned(Tree& out, uint32_t slot, const Work& w) const {
    const Bvh2 bvh = build_binned_sah(w.refs, config_, block_leaf_ > 0);
    Tree sub;
    sub.nodes.assign(bvh.nodes.begin(), bvh.nodes.end());
    sub.ids.reserve(bvh.prim_ids.size());
    for (Bvh2Node& node : sub.nodes) {
      if (!node.is_leaf()) continue;
      const size_t first = sub.ids.size();
      sub.ids.insert(sub.ids.end(), bvh.prim_ids.begin() + node.index,
                     bvh.prim_ids.begin() + node.index + node.count);
      std::sort(sub.ids.begin() + first, sub.ids.end());
      sub.ids.erase(std::unique(sub.ids.begin() + first, sub.ids.end()), sub.ids.end());
      node.index = uint32_t(first);
      node.count = uint32_t(sub.ids.size() - first);
    }
    splice(out, slot, sub);
  }

  static void splice(Tree& out, uint32_t slot, const Tree& sub) {
    const uint32_t node_base = uint32_t(out.nodes.size()) - 1;  // sub node i >= 1 lands here + i
    const uint32_t id_base = uint32_t(out.ids.size());
    auto moved = [&](Bvh2Node node) {
      node.index += node.is_leaf() ? id_base : node_base;
      return node;
    };
    out.nodes[slot] = moved(sub.nodes[0]);
    for (size_t i = 1; i < sub.nodes.size(); ++i) out.nodes.push_back(moved(sub.nodes[i]));
    out.ids.insert(out.ids.end(), sub.ids.begin(), sub.ids.end());
  }

  // A leaf holds each primitive once, whatever number of its parts reached it.
  static void make_leaf(Tree& out, uint32_t slot, Work& w) {
    const size_t first = out.ids.size();
    for (const PrimRef& r : w.refs) out.ids.push_back(r.prim_id);
    std::sort(out.ids.begin() + first, out.ids.end());
    out.ids.erase(std::unique(out.ids.begin() + first, out.ids.end()), out.ids.end());
    const Box& b = w.geom;
    out.nodes[slot] = Bvh2Node{{b.lo[0], b.lo[1], b.lo[2]},
                               uint32_t(first),
                               {b.hi[0], b.hi[1], b.hi[2]},
                               uint32_t(out.ids.size() - first)};
  }

  // Binned over the centroid bounds, the chosen boundary refined exactly for large nodes.
  Split object_split(Work& w, float inv_area) const {
    Split best;
    const size_t n = w.refs.size();
    float ext[3];
    for (int a = 0; a < 3; ++a) ext[a] = w.cent.hi_at(a) - w.cent.lo_at(a);
    if (!(ext[0] > 0.0f) && !(ext[1] > 0.0f) && !(ext[2] > 0.0f)) return best;
    for (int a = 0; a < 3; ++a) {
      if (!(ext[a] > 0.0f)) continue;
      const CentroidBins bin_of_ref(w, a);
      const auto bins = bin_chunks<AxisBins<object_bins>>(n, [&](auto& out, size_t b, size_t e) {
        for (size_t i = b; i < e; ++i) {
          const int k = bin_of_ref(w.refs[i]);
          out.box[k].add(w.refs[i]);
          ++out.entries[k];
        }
      });
      sweep(bins.box, bins.entries, object_bins, a, inv_area, Split::object_binned, best,
            bins.entries);
    }
    if (best.kind == Split::object_binned && n >= refine_min) refine(w, inv_area, best);
    return best;
  }

  // The references of the two bins at boundary `k` (bins k - 1 and k), by centroid and then
  // position (a total order, so evaluation and partition see the same sequence).
  static void boundary_order(const Work& w, int a, int k, std::vector<uint32_t>& middle) {
    const CentroidBins bin_of_ref(w, a);
    middle.clear();
    for (size_t i = 0; i < w.refs.size(); ++i) {
      const int b = bin_of_ref(w.refs[i]);
      if (b == k - 1 || b == k) middle.push_back(uint32_t(i));
    }
    std::sort(middle.begin(), middle.end(), [&](uint32_t x, uint32_t y) {
      const float cx = centroid(w.refs[x], a), cy = centroid(w.refs[y], a);
      return cx < cy || (cx == cy && x < y);
    });
  }

  // Every split among the boundary bins' sorted references (the binned one among them).
  void refine(const Work& w, float inv_area, Split& s) const {
    const int a = s.axis, k = s.index;
    std::vector<uint32_t> middle;
    boundary_order(w, a, k, middle);
    const CentroidBins bin_of_ref(w, a);
    Box lower, upper;
    size_t n_lower = 0, n_upper = 0;
    for (const PrimRef& r : w.refs) {
      const int b = bin_of_ref(r);
      if (b < k - 1) {
        lower.add(r);
        ++n_lower;
      } else if (b > k) {
        upper.add(r);
        ++n_upper;
      }
    }
    const size_t m = middle.size();
    std::vector<Box> suffix(m + 1);
    suffix[m] = upper;
    for (size_t i = m; i-- > 0;) {
      suffix[i] = suffix[i + 1];
      suffix[i].add(w.refs[middle[i]]);
    }
    Box prefix = lower;
    bool refined = false;
    for (size_t i = 0; i <= m; ++i) {
      if (i > 0) prefix.add(w.refs[middle[i - 1]]);
      const size_t nl = n_lower + i, nr = n_upper + m - i;
      if (nl == 0 || nr == 0) continue;
      const float cost = split_cost(config_, inv_area, prefix.area(), nl, suffix[i].area(), nr);
      if (cost < s.cost) {
        s = Split{Split::object_refined, a, k, cost, prefix, suffix[i], nl, nr};
        s.middle_left = i;
        refined = true;
      }
    }
    if (refined) s.middle = std::move(middle);  // the partition's order
  }

  // Right-to-left suffix boxes, then left-to-right costs; `exits` counts the references
  // leaving each bin (spatial) or equals `count` (object splits).
  void sweep(const Box* bins, const uint32_t* entries, int bin_count, int axis, float inv_area,
             Split::Kind kind, Split& best, const uint32_t* exits) const {
    Box suffix[object_bins];
    uint32_t right_count[object_bins];
    Box acc;
    uint32_t c = 0;
    for (int b = bin_count - 1; b > 0; --b) {
      acc.add(bins[b]);
      c += exits[b];
      suffix[b] = acc;
      right_count[b] = c;
    }
    acc = Box{};
    c = 0;
    for (int b = 0; b + 1 < bin_count; ++b) {
      acc.add(bins[b]);
      c += entries[b];
      if (c == 0 || right_count[b + 1] == 0) continue;
      const float cost =
          split_cost(config_, inv_area, acc.area(), c, suffix[b + 1].area(), right_count[b + 1]);
      if (cost < best.cost) {
        best = Split{kind, axis, b + 1, cost, acc, suffix[b + 1], c, right_count[b + 1]};
      }
    }
  }

  // The node's box cut into spatial_bins slabs per axis; a reference is clipped into each
  // slab it crosses, counted as entering its first and leaving its last.
  void spatial_split(Work& w, float inv_area, Split& best) const {
    Split candidate = best;
    for (int a = 0; a < 3; ++a) {
      const float lo = w.geom.lo_at(a), ext = w.geom.hi_at(a) - lo;
      if (!(ext > 0.0f)) continue;
      const float width = ext / float(spatial_bins), inv_width = float(spatial_bins) / ext;
      const auto bins =
          bin_chunks<AxisBins<spatial_bins>>(w.refs.size(), [&](auto& out, size_t b, size_t e) {
            for (size_t i = b; i < e; ++i) {
              const PrimRef& r = w.refs[i];
              const int first = bin_of(at(r.lo, a), lo, inv_width);
              const int last = std::max(first, bin_of(at(r.hi, a), lo, inv_width));
              if (first == last) {
                out.box[first].add(r);
                ++out.entries[first];
                ++out.exits[first];
                continue;
              }
              const auto [start, end] =
                  slab_parts(r, a, lo, width, inv_width, first, last, out.box);
              ++out.entries[start];
              ++out.exits[end];
            }
          });
      sweep(bins.box, bins.entries, spatial_bins, a, inv_area, Split::spatial, candidate,
            bins.exits);
    }
    // A split that could create more references than the budget allows is not taken.
    if (candidate.kind == Split::spatial &&
        candidate.left_count + candidate.right_count - w.refs.size() <= w.budget)
      best = candidate;
  }

  static int bin_of(float x, float lo, float inv_width) {
    return std::clamp(int((x - lo) * inv_width), 0, spatial_bins - 1);
  }

  // Adds the bounds of r's part in each slab it crosses (first..last, of `width` from `lo`)
  // to that slab's bin (ReferenceClipper::slab_bounds, kept within the slab and r's box).
  // Returns the first and last slab that received a part.
  std::pair<int, int> slab_parts(const PrimRef& r, int a, float lo, float width, float inv_width,
                                 int first, int last, Box* bins) const {
    Bounds3 part[spatial_bins];
    split_.slab_bounds(r, a, lo, width, inv_width, first, last, part);
    int start = -1, end = first;
    for (int b = first; b <= last; ++b) {
      PrimRef clipped = r;
      clipped.lo = max(part[b].lo, r.lo);
      clipped.hi = min(part[b].hi, r.hi);
      at(clipped.lo, a) = std::max(at(clipped.lo, a), lo + float(b) * width);
      at(clipped.hi, a) = std::min(at(clipped.hi, a), lo + float(b + 1) * width);
      if (is_empty(Bounds3{clipped.lo, clipped.hi})) continue;
      bins[b].add(clipped);
      if (start < 0) start = b;
      end = b;
    }
    if (start < 0) {  // rounding left no part: count it whole in its first slab
      bins[first].add(r);
      return {first, first};
    }
    return {start, end};
  }

  void partition_object(Work& w, const Split& s, Work& left, Work& right) const {
    const size_t n = w.refs.size();
    if (s.kind == Split::none) {  // all centroids equal: halves by count
      for (size_t i = 0; i < n; ++i) (i < n / 2 ? left : right).add(w.refs[i]);
      return;
    }
    const int a = s.axis;
    const CentroidBins bin_of_ref(w, a);
    if (s.kind == Split::object_refined) {
      for (const PrimRef& r : w.refs) {
        const int b = bin_of_ref(r);
        if (b < s.index - 1) left.add(r);
        if (b > s.index) right.add(r);
      }
      for (size_t i = 0; i < s.middle.size(); ++i)
        (i < s.middle_left ? left : right).add(w.refs[s.middle[i]]);
      return;
    }
    for (const PrimRef& r : w.refs) (bin_of_ref(r) < s.index ? left : right).add(r);
  }

  // Returns the number of references created. A reference crossing the plane is split, or
  // kept whole on one side when that costs less (Stich et al.'s unsplitting).
  size_t partition_spatial(Work& w, const Split& s, Work& left, Work& right) const {
    const int a = s.axis;
    const float lo = w.geom.lo_at(a), ext = w.geom.hi_at(a) - lo;
    const float inv_width = float(spatial_bins) / ext;
    const float pos = lo + float(s.index) * (ext / float(spatial_bins));
    const float al = s.left.area(), ar = s.right.area();
    const float nl = float(s.left_count), nr = float(s.right_count);
    size_t created = 0;
    for (const PrimRef& r : w.refs) {
      const int first = bin_of(at(r.lo, a), lo, inv_width);
      const int last = std::max(first, bin_of(at(r.hi, a), lo, inv_width));
      if (last < s.index) {
        left.add(r);
        continue;
      }
      if (first >= s.index) {
        right.add(r);
        continue;
      }
      Box with = box_of(r);
      Box l = with, rr = with;
      l.add(s.left);
      rr.add(s.right);
      const float split = al * nl + ar * nr;
      const float whole_left = l.area() * nl + ar * (nr - 1.0f);
      const float whole_right = al * (nl - 1.0f) + rr.area() * nr;
      if (whole_left <= split && whole_left <= whole_right) {
        left.add(r);
        continue;
      }
      if (whole_right <= split) {
        right.add(r);
        continue;
      }
      PrimRef pl, pr;
      bool only_left = false;
      if (split_.split(r, a, pos, pl, pr, only_left)) {
        left.add(pl);
        right.add(pr);
        ++created;
      } else {
        (only_left ? left : right).add(r);
      }
    }
    return created;
  }

  const BuildConfig& config_;
  ReferenceClipper split_;
  size_t block_leaf_;
  float min_overlap_;
};

}  // namespace

Bvh2 build_spatial_sah(std::span<const PrimRef> refs, std::span<const Triangle> triangles,
                       const BuildConfig& config, bool block_leaves) {
  Work root;
  root.refs.reserve(refs.size());
  for (const PrimRef& r : refs) root.add(r);
  root.budget = size_t(float(refs.size()) * split_budget);
  SpatialBuilder builder(config, ReferenceClipper{triangles}, block_leaves ? 4 : 0,
                         root.geom.area());
  Tree tree;
  tree.nodes.resize(1);
  builder.build(tree, 0, root);
  Bvh2 out;
  out.nodes = Buffer<Bvh2Node>(tree.nodes.begin(), tree.nodes.end());
  out.prim_ids = std::move(tree.ids);
  return out;
}

}  // namespace kestrel
