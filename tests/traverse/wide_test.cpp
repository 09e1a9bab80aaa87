// Every wide layout and every ISA kernel against the scalar Bvh2 reference, ray by ray:
// closest hits must be identical (t bit for bit, prim id, barycentrics), any-hit queries must
// agree on hit or miss. Refit against a fresh build and brute force; layout byte sizes.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>

#include "bvh/builders.h"
#include "common/ray_gen.h"
#include "common/views.h"
#include "core/vec.h"
#include "geometry/prim_ref.h"
#include "kestrel/error.h"
#include "kestrel/kestrel.h"
#include "support/oracles.h"
#include "traverse/accel_nodes.h"
#include "traverse/batches.h"
#include "traverse/kernels.h"
#include "traverse/wide_bvh.h"

namespace kestrel {
namespace {

using test::build_layout;
using test::float_bits;

// Traces rays through every (layout, ISA) and compares with the Bvh2 reference.
void expect_same_as_reference(const Scene& scene, std::span<const Ray> rays, Builder builder,
                              const std::string& what) {
  const Accel ref = build_layout(scene, builder, Layout::bvh2);
  std::vector<Hit> want(rays.size()), want_any(rays.size());
  trace(ref, rays, want, false);
  trace(ref, rays, want_any, true);
  size_t hits = 0;
  for (const Hit& h : want) hits += h.hit();
  for (Layout layout : {Layout::bvh4, Layout::bvh8}) {
    const Accel wide = build_layout(scene, builder, layout);
    for (Isa isa : test::supported_isas()) {
      SCOPED_TRACE(what + " " + layout_name(layout) + " " + isa_name(isa) + " " +
                   builder_name(builder));
      // Packets auto / off / on, stream off / on (stream on with packets auto: ray streams).
      for (int mode = 0; mode < 6; ++mode) {
        const std::optional<bool> packets =
            mode % 3 == 0 ? std::nullopt : std::optional<bool>(mode % 3 == 2);
        const bool stream = mode >= 3;
        std::vector<Hit> got(rays.size());
        TraceOptions opt;
        opt.isa = isa;
        opt.packets = packets;
        opt.stream = stream;
        trace(wide, rays, got, opt);
        for (size_t i = 0; i < rays.size(); ++i) {
          ASSERT_EQ(got[i].prim_id, want[i].prim_id)
              << "ray " << i << " packets " << (packets ? int(*packets) : -1) << " stream "
              << stream;
          ASSERT_EQ(float_bits(got[i].t), float_bits(want[i].t))
              << "ray " << i << " t " << got[i].t << " vs " << want[i].t;
          ASSERT_EQ(got[i].u, want[i].u) << "ray " << i;
          ASSERT_EQ(got[i].v, want[i].v) << "ray " << i;
        }
      }
      for (int mode = 0; mode < 6; ++mode) {  // packets auto / off / on, stream off / on
        const std::optional<bool> packets =
            mode % 3 == 0 ? std::nullopt : std::optional<bool>(mode % 3 == 2);
        const bool stream = mode >= 3;
        std::vector<uint8_t> occ(rays.size());
        TraceOptions opt;
        opt.isa = isa;
        opt.packets = packets;
        opt.stream = stream;
        occluded(wide, rays, occ, opt);
        for (size_t i = 0; i < rays.size(); ++i)
          ASSERT_EQ(bool(occ[i]), want_any[i].hit())
              << "ray " << i << " packets " << (packets ? int(*packets) : -1) << " stream "
              << stream;
      }
      // Both orders of single-ray occlusion (occluded() times them and takes the faster), each
      // called directly: children in slot order and nearest first.
      const kernels::Table& k = kernels::table_for(isa);
      for (bool nearest : {false, true}) {
        std::vector<Hit> got(rays.size());
        kernels::for_each_traceable_run(rays, got.data(), [&](const Ray* r, Hit* h, size_t n) {
          if (layout == Layout::bvh4)
            (nearest ? k.any_nearest4 : k.any4)(wide.nodes->bvh4.nodes.data(),
                                                wide.nodes->bvh4.blocks.data(), r, h, n);
          else
            (nearest ? k.any_nearest8 : k.any8)(wide.nodes->bvh8.nodes.data(),
                                                wide.nodes->bvh8.blocks.data(), r, h, n);
        });
        for (size_t i = 0; i < rays.size(); ++i)
          ASSERT_EQ(got[i].hit(), want_any[i].hit()) << "ray " << i << " nearest " << nearest;
      }
    }
  }
  EXPECT_GT(hits, rays.size() / 20) << what;  // the comparison is not vacuous
}

TEST(WideKernels, RandomSoupAllBuilders) {
  const Scene scene = test::random_soup(3000, 0.15f, 7);
  const std::vector<Ray> rays = test::random_rays(4000, 8);
  for (Builder b : test::all_builders()) expect_same_as_reference(scene, rays, b, "soup");
}

TEST(WideKernels, ClosedBoxAxisParallelAndEdgeRays) {
  // Rays along box faces and through its edges and corners: ties between the triangles
  // that share an edge must resolve the same (smallest prim id) in every kernel.
  const Scene scene = test::closed_box({0, 0, 0}, {1, 1, 1});
  std::vector<Ray> rays;
  for (float a : {0.0f, 0.25f, 0.5f, 1.0f})
    for (float b : {0.0f, 0.5f, 1.0f}) {
      rays.push_back({{-1, a, b}, {1, 0, 0}});
      rays.push_back({{a, -1, b}, {0, 1, 0}});
      rays.push_back({{a, b, 2}, {0, 0, -1}});
      rays.push_back({{0.5f, 0.5f, 0.5f}, {a - 0.5f, b - 0.5f, 0.5f}});
      rays.push_back({{-1, -1, -1}, {a + 1, b + 1, 2}});
    }
  expect_same_as_reference(scene, rays, Builder::sweep, "box");
  // A box is one Bvh2 leaf with the default config: test multi-level trees too.
  const Scene sphere = test::closed_sphere(4, {0, 0, 0}, 1.0f);
  std::vector<Ray> srays;
  test::Rng rng{3};
  for (int i = 0; i < 3000; ++i) {
    const Vec3 o = rng.on_sphere() * 3.0f;
    srays.push_back({o, rng.on_sphere() * 0.3f - o});
  }
  expect_same_as_reference(sphere, srays, Builder::binned, "sphere");
}

TEST(WideKernels, EmptySceneAndSingleTriangle) {
  Scene empty;
  Scene one;
  TriangleMesh m;
  m.positions = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}};
  m.indices = {0, 1, 2};
  one.meshes.push_back(m);
  const Ray r{{0.2f, 0.2f, -1}, {0, 0, 1}};
  for (Layout layout : {Layout::bvh2, Layout::bvh4, Layout::bvh8}) {
    EXPECT_FALSE(intersect(build_layout(empty, Builder::binned, layout), r).hit());
    const Hit h = intersect(build_layout(one, Builder::binned, layout), r);
    EXPECT_EQ(h.prim_id, 0u);
    EXPECT_FLOAT_EQ(h.t, 1.0f);
  }
}

// The shared scenes when present; always the built-in Cornell box and a synthetic room (a
// closed box around a sphere and a soup: rays bounce inside, as in an interior).
TEST(WideKernels, ScenesPrimaryShadowDiffuse) {
  std::vector<std::pair<std::string, Scene>> scenes;
  for (const char* rel :
       {"teapot/teapot.obj", "cornell_box/cornell_box.obj", "dabrovic_sponza/sponza.obj"})
    if (auto path = test::shared_scene(rel)) scenes.emplace_back(rel, load_scene(*path));
  scenes.emplace_back("builtin:cornell_box", load_scene("builtin:cornell_box"));
  Scene room = test::closed_box({-2, -1, -2}, {2, 2, 2});
  room.meshes.push_back(test::closed_sphere(3, {0.3f, 0, 0.2f}, 0.6f).meshes[0]);
  room.meshes.push_back(test::random_soup(400, 0.15f, 9).meshes[0]);
  room.source = "synthetic room";
  scenes.emplace_back("synthetic room", std::move(room));
  for (const auto& [rel, scene] : scenes) {
    const std::string view = rel.find("sponza") != std::string::npos ? "inside" : "framing";
    auto cam = rel == "synthetic room"
                   ? std::optional(tools::PinholeCamera{{-1.5f, 0.5f, -1.5f}, {0.3f, 0, 0.2f}, 70})
                   : tools::named_view(scene, view);
    ASSERT_TRUE(cam.has_value());
    BuildConfig c;
    c.layout = Layout::bvh2;
    const Accel ref = build_accel(scene, c);
    std::vector<Ray> rays = tools::primary_rays(*cam, 96, 64);
    const std::vector<Ray> primary = rays;
    for (auto kind : {tools::RayKind::shadow, tools::RayKind::diffuse}) {
      auto more = tools::secondary_rays(ref, scene, primary, kind,
                                        tools::default_light(tools::scene_bounds(scene)), 11);
      rays.insert(rays.end(), more.begin(), more.end());
    }
    expect_same_as_reference(scene, rays, Builder::binned, rel);
  }
}

// Packets of 16 (8) rays decide with the packet's frustum (interval bounds over its rays):
// alone where the frustum is tight, before the per-ray tests otherwise. Every shape of packet
// those paths distinguish must give the single rays' hits: fans from one point (tight), with
// per-ray tmin / tmax; parallel rays from a grid of origins (an orthographic camera), close
// together and spread over the scene; rays converging on a point (shadow rays); rays with a
// zero or negative-zero direction component (no frustum); and a fan whose rays stop short.
TEST(WideKernels, PacketFrustumShapesMatchTheReference) {
  Scene scene = test::closed_box({-2, -1, -2}, {2, 2, 2});
  scene.meshes.push_back(test::closed_sphere(4, {0.3f, 0, 0.2f}, 0.6f).meshes[0]);
  scene.meshes.push_back(test::random_soup(3000, 0.08f, 5).meshes[0]);
  test::Rng rng{17};
  std::vector<Ray> rays;
  auto fan = [&](Vec3 eye, Vec3 centre, float width, int count, bool vary_range) {
    for (int i = 0; i < count; ++i) {
      const float s = width * (float(i % 16) / 15.0f - 0.5f), r = width * (float(i / 16) - 0.5f);
      Ray ray{eye, centre - eye + Vec3{s, r * 0.5f, s * 0.3f}};
      if (vary_range) ray.tmin = 0.05f * rng.uniform(), ray.tmax = 0.5f + 3.0f * rng.uniform();
      rays.push_back(ray);
    }
  };
  fan({-1.8f, 0.5f, -1.8f}, {0.3f, 0, 0.2f}, 0.05f, 64, false);     // narrow: tight
  fan({-1.8f, 0.5f, -1.8f}, {0.3f, 0, 0.2f}, 0.05f, 64, true);      // with tmin / tmax
  fan({1.5f, -0.5f, 1.7f}, {-1.0f, 1.0f, -1.0f}, 1.5f, 64, false);  // wide: not tight
  for (int k = 0; k < 24; ++k)  // into the soup from all sides, tight but not narrow
    fan(Vec3{0.5f, 0.5f, 0.5f} + rng.on_sphere() * 1.4f, {0.5f, 0.5f, 0.5f}, 0.08f, 64, k % 2);
  for (float spacing : {0.001f, 0.2f})  // orthographic
    for (int i = 0; i < 64; ++i)
      rays.push_back({{-1.9f, spacing * float(i % 8) - 0.5f, spacing * float(i / 8) - 0.9f},
                      {1, 0.02f, 0.01f}});
  const Vec3 light{0.1f, 1.9f, 0.1f};
  for (int i = 0; i < 64; ++i) {  // shadow rays from a patch and from all over the room
    const Vec3 near{-1.0f + 0.01f * float(i % 8), -0.99f, -1.0f + 0.01f * float(i / 8)};
    const Vec3 far{-1.9f + 3.8f * rng.uniform(), -0.99f, -1.9f + 3.8f * rng.uniform()};
    for (Vec3 o : {near, far}) rays.push_back({o, light - o, 1e-4f, 1.0f});
  }
  for (float zero : {0.0f, -0.0f})  // a zero component in every ray of the packet
    for (int i = 0; i < 32; ++i)
      rays.push_back({{-1.9f, 0.01f * float(i), 0.3f}, {1, 0.001f * float(i), zero}});
  for (int i = 0; i < 16; ++i)  // a packet with one axis-parallel ray among oblique ones
    rays.push_back({{-1.9f, 0.2f, 0.3f}, {1, i == 7 ? 0.0f : 0.01f * float(i), 0.02f}});
  expect_same_as_reference(scene, rays, Builder::binned, "packet shapes");
}

TEST(WideLayout, NodeSizes) {
  EXPECT_EQ(sizeof(Bvh4Node), 112u);
  EXPECT_EQ(sizeof(Bvh8Node), 224u);
  EXPECT_EQ(sizeof(TriangleBlock), 160u);
  EXPECT_EQ(alignof(Bvh8Node), 32u);
}

TEST(WideLayout, EveryPrimitiveInExactlyOneLeafAndBoxesEnclose) {
  const Scene scene = test::random_soup(5000, 0.1f, 21);
  const test::Soup soup = test::flatten(scene);
  for (Layout layout : {Layout::bvh4, Layout::bvh8}) {
    const Accel a = build_layout(scene, Builder::binned, layout);
    const int W = layout == Layout::bvh4 ? 4 : 8;
    std::vector<int> seen(soup.triangles.size(), 0);
    const size_t node_count = W == 4 ? a.nodes->bvh4.nodes.size() : a.nodes->bvh8.nodes.size();
    const auto& blocks = W == 4 ? a.nodes->bvh4.blocks : a.nodes->bvh8.blocks;
    size_t children = 0;
    for (size_t i = 0; i < node_count; ++i) {
      for (int j = 0; j < W; ++j) {
        const uint32_t ref =
            W == 4 ? a.nodes->bvh4.nodes[i].child[j] : a.nodes->bvh8.nodes[i].child[j];
        auto bound = [&](int row) {
          return W == 4 ? a.nodes->bvh4.nodes[i].bounds[row][j]
                        : a.nodes->bvh8.nodes[i].bounds[row][j];
        };
        if (ref == wide_empty) continue;
        ++children;
        if (!(ref & wide_leaf_bit)) {
          ASSERT_GT(ref, i) << "children follow their parent";
          continue;
        }
        for (size_t b = ref & ~wide_leaf_bit;; ++b) {
          ASSERT_LT(b, blocks.size());
          for (int lane = 0; lane < 4; ++lane) {
            const uint32_t id = blocks[b].prim_id[lane] & ~block_last_bit;
            if (lane == 0 || id != (blocks[b].prim_id[lane - 1] & ~block_last_bit)) ++seen[id];
            for (int v = 0; v < 3; ++v)
              for (int ax = 0; ax < 3; ++ax) {
                ASSERT_GE(blocks[b].v[v][ax][lane], bound(2 * ax));
                ASSERT_LE(blocks[b].v[v][ax][lane], bound(2 * ax + 1));
              }
          }
          if (blocks[b].prim_id[0] & block_last_bit) break;
        }
      }
    }
    for (size_t id = 0; id < seen.size(); ++id)
      ASSERT_EQ(seen[id], soup.valid[id] ? 1 : 0) << "prim " << id;
    EXPECT_EQ(
        children, node_count - 1 + [&] {
          size_t leaves = 0;
          for (size_t i = 0; i < node_count; ++i)
            for (int j = 0; j < W; ++j) {
              const uint32_t ref =
                  W == 4 ? a.nodes->bvh4.nodes[i].child[j] : a.nodes->bvh8.nodes[i].child[j];
              leaves += ref != wide_empty && (ref & wide_leaf_bit);
            }
          return leaves;
        }());
  }
}

// Moves every vertex, refits, and compares against a fresh build over the moved scene
// (same hits) and brute force.
TEST(WideBuild, StoppingAtFourGivesTheSameWideTree) {
  // build_accel's wide layouts build with build_bvh_for_blocks (binned: ranges <= 4 become
  // leaves; lbvh: emission stops at subtrees <= 4). The collapse makes every subtree of <= 4
  // primitives one block anyway, so the wide tree must be the one collapsed from the full
  // binary tree: same nodes, same blocks, same SAH cost.
  for (uint64_t seed : {3u, 8u})
    for (Builder builder : {Builder::binned, Builder::lbvh}) {
      const Scene scene = test::random_soup(seed == 3 ? 5000 : 20000, 0.05f, seed);
      BuildConfig c;
      c.builder = builder;
      SceneValidation validation;
      const Buffer<PrimRef> refs = validate_and_make_prim_refs(scene, validation);
      const Bvh2 full = build_bvh(refs, c), blocks = build_bvh_for_blocks(refs, {}, c);
      EXPECT_LT(blocks.nodes.size(), full.nodes.size()) << builder_name(builder);
      const Bvh8 a =
          collapse_to_bvh8(full, gather_triangles(scene, full.prim_ids), c.max_leaf_size);
      const Bvh8 b =
          collapse_to_bvh8(blocks, gather_triangles(scene, blocks.prim_ids), c.max_leaf_size);
      ASSERT_EQ(a.nodes.size(), b.nodes.size()) << builder_name(builder);
      ASSERT_EQ(a.blocks.size(), b.blocks.size()) << builder_name(builder);
      EXPECT_EQ(wide_sah_cost(a), wide_sah_cost(b)) << builder_name(builder);
      for (size_t i = 0; i < a.nodes.size(); ++i)
        ASSERT_EQ(0, std::memcmp(&a.nodes[i], &b.nodes[i], sizeof(Bvh8Node)))
            << builder_name(builder) << " node " << i;
    }
}

// The LBVH's direct wide build (traverse/morton_wide.h): the same bytes with one thread and
// with four, every triangle in a block, exact hits against the Bvh2 reference on a soup big
// enough for several levels of top nodes and dozens of tasks, and the smallest scenes (one to
// five triangles: a root with one leaf, then a split).
template <class Wide>
void expect_same_wide(const Wide& a, const Wide& b, size_t prims, const std::string& what) {
  ASSERT_EQ(a.nodes.size(), b.nodes.size()) << what;
  ASSERT_EQ(a.blocks.size(), b.blocks.size()) << what;
  ASSERT_EQ(0, std::memcmp(a.nodes.data(), b.nodes.data(), a.nodes.size() * sizeof(a.nodes[0])))
      << what;
  ASSERT_EQ(0,
            std::memcmp(a.blocks.data(), b.blocks.data(), a.blocks.size() * sizeof(TriangleBlock)))
      << what;
  std::vector<int> seen(prims, 0);
  for (const TriangleBlock& blk : a.blocks)
    for (int lane = 0; lane < 4; ++lane) seen.at(blk.prim_id[lane] & ~block_last_bit) = 1;
  EXPECT_EQ(std::count(seen.begin(), seen.end(), 1), ptrdiff_t(prims)) << what;
}

// build_accel(scene, c) gives the same wide tree bytes with one thread and with four.
void expect_thread_independent(const Scene& scene, const BuildConfig& c, size_t prims,
                               const std::string& what) {
  Accel one, four;
  {
    ThreadLimit l(1);
    one = build_accel(scene, c);
  }
  {
    ThreadLimit l(4);
    four = build_accel(scene, c);
  }
  if (c.layout == Layout::bvh4)
    expect_same_wide(one.nodes->bvh4, four.nodes->bvh4, prims, what);
  else
    expect_same_wide(one.nodes->bvh8, four.nodes->bvh8, prims, what);
}

TEST(WideBuild, DirectMortonBuildIsExactAndThreadIndependent) {
  for (size_t n : {size_t(1), size_t(4), size_t(5), size_t(60000)}) {
    const Scene scene = test::random_soup(n, n > 100 ? 0.02f : 0.6f, 11 + n);
    for (Layout layout : {Layout::bvh4, Layout::bvh8})
      for (uint32_t bits : {30u, 63u}) {
        BuildConfig c;
        c.builder = Builder::lbvh;
        c.layout = layout;
        c.morton_bits = bits;
        expect_thread_independent(
            scene, c, n,
            std::to_string(n) + " " + layout_name(layout) + " " + std::to_string(bits) + " bits");
      }
    if (n >= 5)
      expect_same_as_reference(scene, test::random_rays(3000, n), Builder::lbvh, "direct");
  }
  // Several meshes (the blocks read each triangle from its own mesh by global id), one of them
  // empty, and invalid triangles left out.
  const Scene soup = test::random_soup(20000, 0.03f, 7);
  const TriangleMesh& all = soup.meshes[0];
  Scene split;
  const size_t ranges[4][2] = {{0, 2000}, {2000, 2000}, {2000, 11000}, {11000, 20000}};
  for (const auto& [b, e] : ranges) {
    TriangleMesh m;
    m.positions = all.positions;
    m.indices.assign(all.indices.begin() + std::ptrdiff_t(3 * b),
                     all.indices.begin() + std::ptrdiff_t(3 * e));
    split.meshes.push_back(std::move(m));
  }
  split.meshes[2].indices[3] = split.meshes[2].indices[4] =
      split.meshes[2].indices[5];  // zero area
  expect_same_as_reference(split, test::random_rays(3000, 8), Builder::lbvh, "direct, 4 meshes");
}

// `scene`'s one mesh cut into meshes of uneven sizes (an empty one among them), each with
// its own copy of the vertices.
Scene cut_into_meshes(const Scene& scene) {
  const TriangleMesh& whole = scene.meshes[0];
  Scene out;
  for (size_t t = 0, size = 1; t < whole.triangle_count(); size = size * 3 + 7) {
    TriangleMesh& mesh = out.meshes.emplace_back();
    if (out.meshes.size() == 3) continue;  // empty
    const size_t end = std::min(whole.triangle_count(), t + size);
    for (; t < end; ++t)
      for (int k = 0; k < 3; ++k) {
        mesh.indices.push_back(uint32_t(mesh.positions.size()));
        mesh.positions.push_back(whole.positions[whole.indices[3 * t + k]]);
      }
  }
  return out;
}

// The build compacts its slots, the collapse plans its leaves and builds its wide nodes and
// blocks in parallel tasks (blocks straight from the meshes): the same bytes with one thread
// and with four, and the same bytes as a collapse from a gathered copy of the leaf triangles
// (the other entry point, which spatial splits use). The binned build's scene is spread over
// many meshes (references made in chunks across them).
TEST(WideBuild, CollapsedBuildsAreThreadIndependent) {
  const Scene scene = test::random_soup(60000, 0.02f, 29);
  const Scene large = cut_into_meshes(test::random_soup(150000, 0.01f, 31));
  ASSERT_GT(large.meshes.size(), 8u);
  for (Builder builder : {Builder::binned, Builder::spatial})
    for (Layout layout : {Layout::bvh4, Layout::bvh8}) {
      BuildConfig c;
      c.builder = builder;
      c.layout = layout;
      const Scene& s = builder == Builder::binned ? large : scene;
      expect_thread_independent(s, c, s.triangle_count(),
                                std::string(builder_name(builder)) + " " + layout_name(layout));
    }
  BuildConfig c;
  SceneValidation validation;
  const Buffer<PrimRef> refs = validate_and_make_prim_refs(scene, validation);
  const Bvh2 bvh = build_bvh_for_blocks(refs, {}, c);
  expect_same_wide(collapse_to_bvh8(bvh, scene, c.max_leaf_size),
                   collapse_to_bvh8(bvh, gather_triangles(scene, bvh.prim_ids), c.max_leaf_size),
                   bvh.prim_ids.size(), "from the meshes / from gathered triangles");
}

TEST(Refit, MatchesFreshBuildOnEveryLayout) {
  Scene scene = test::random_soup(2000, 0.12f, 5);
  const std::vector<Ray> rays = test::random_rays(2000, 6);
  for (Layout layout : {Layout::bvh2, Layout::bvh4, Layout::bvh8}) {
    Scene moving = scene;
    Accel accel = build_layout(moving, Builder::binned, layout);
    for (Vec3& p : moving.meshes[0].positions)
      p = {p.x + 0.3f * p.y * p.y, p.y * 0.8f + 0.1f, p.z - 0.2f * p.x};
    refit_accel(accel, moving);
    const Accel fresh = build_layout(moving, Builder::binned, Layout::bvh2);
    const test::Soup soup = test::flatten(moving);
    std::vector<Hit> got(rays.size()), want(rays.size());
    trace(accel, rays, got, false);
    trace(fresh, rays, want, false);
    size_t hits = 0;
    for (size_t i = 0; i < rays.size(); ++i) {
      ASSERT_EQ(got[i].prim_id, want[i].prim_id) << layout_name(layout) << " ray " << i;
      ASSERT_EQ(float_bits(got[i].t), float_bits(want[i].t));
      const Hit brute = intersect_brute_force(soup.triangles, soup.valid, rays[i], false);
      ASSERT_EQ(got[i].prim_id, brute.prim_id);
      hits += got[i].hit();
    }
    EXPECT_GT(hits, rays.size() / 20);
    const Bounds3 b = accel.bounds;
    EXPECT_EQ(b.lo.x, fresh.bounds.lo.x);
    EXPECT_EQ(b.hi.y, fresh.bounds.hi.y);
  }
}

TEST(Refit, ChangedTopologyOrInvalidVertexIsAClearError) {
  Scene scene = test::random_soup(100, 0.2f, 2);
  Accel accel = build_layout(scene, Builder::binned, Layout::bvh8);
  Scene more = scene;
  more.meshes[0].indices.insert(more.meshes[0].indices.end(), {0, 1, 2});
  EXPECT_THROW(refit_accel(accel, more), Error);
  Scene nan = scene;
  nan.meshes[0].positions[nan.meshes[0].indices[0]].x = std::nanf("");
  try {
    refit_accel(accel, nan);
    FAIL() << "expected an error";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("no longer valid"), std::string::npos) << e.what();
  }
}

TEST(Dispatch, IsaNamesAndUnsupportedIsaIsAnError) {
  for (Isa isa : {Isa::sse2, Isa::avx2, Isa::avx512}) EXPECT_EQ(isa_from_name(isa_name(isa)), isa);
  EXPECT_FALSE(isa_from_name("avx3").has_value());
  EXPECT_TRUE(isa_supported(Isa::sse2));
  EXPECT_TRUE(isa_supported(host_isa()));
  const Accel a = build_layout(test::random_soup(10, 0.3f, 1), Builder::binned, Layout::bvh8);
  std::vector<Ray> rays(3);
  std::vector<Hit> hits(2);
  EXPECT_THROW(trace(a, rays, hits), Error);  // sizes differ
}

// The two-pass refit: the SAH it returns is wide_sah_cost of the result, and the nodes and
// blocks are the same bytes for one thread and two (blocks are rewritten in parallel chunks).
TEST(Refit, ReturnsTheSahCostAndIsThreadCountIndependent) {
  Scene scene = test::random_soup(40000, 0.02f, 9);
  for (Layout layout : {Layout::bvh4, Layout::bvh8}) {
    Scene moving = scene;
    for (Vec3& p : moving.meshes[0].positions) p = {p.x * 1.1f, p.y + 0.05f * p.x * p.z, p.z};
    Accel one = build_layout(scene, Builder::binned, layout),
          two = build_layout(scene, Builder::binned, layout);
    double cost_one, cost_two;
    {
      ThreadLimit limit(1);
      cost_one = refit_accel_cost(one, moving);
    }
    {
      ThreadLimit limit(2);
      cost_two = refit_accel_cost(two, moving);
    }
    EXPECT_EQ(cost_one, cost_two);
    const auto same_bytes = [](const auto& a, const auto& b) {
      return a.size() == b.size() && std::memcmp(a.data(), b.data(), sizeof(a[0]) * a.size()) == 0;
    };
    if (layout == Layout::bvh4) {
      EXPECT_NEAR(cost_one, wide_sah_cost(one.nodes->bvh4), 1e-12 * cost_one);
      EXPECT_TRUE(same_bytes(one.nodes->bvh4.nodes, two.nodes->bvh4.nodes));
      EXPECT_TRUE(same_bytes(one.nodes->bvh4.blocks, two.nodes->bvh4.blocks));
    } else {
      EXPECT_NEAR(cost_one, wide_sah_cost(one.nodes->bvh8), 1e-12 * cost_one);
      EXPECT_TRUE(same_bytes(one.nodes->bvh8.nodes, two.nodes->bvh8.nodes));
      EXPECT_TRUE(same_bytes(one.nodes->bvh8.blocks, two.nodes->bvh8.blocks));
    }
    EXPECT_GT(cost_one, 1.0);
  }
}

}  // namespace
}  // namespace kestrel
