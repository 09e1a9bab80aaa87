// Stream mode against single rays: the same hits in the caller's order (closest and any hit,
// ties, mid-size batches timed each way, more rays than one sort group) and the trace order's
// grouping.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>

#include "kestrel/kestrel.h"
#include "support/oracles.h"
#include "traverse/stream.h"

namespace kestrel {
namespace {

using test::build_layout;
using test::float_bits;

// Stream mode: the same hits, in the caller's
// order, as single rays, for closest and any hit, on 1 and 2 threads, with untraceable rays
// and origins outside the scene box.
TEST(StreamMode, IncoherentBatchesGetTheSameHitsInTheCallersOrder) {
  const Scene scene = test::random_soup(4000, 0.1f, 21);
  std::vector<Ray> rays = test::random_rays(60000, 22);
  for (size_t i = 0; i < rays.size(); i += 997) rays[i].org.x = std::nanf("");
  for (size_t i = 5; i < rays.size(); i += 1009) rays[i].org = rays[i].org * 40.0f;
  for (size_t i = 7; i < rays.size(); i += 1013) rays[i].dir = {0, 0, 0};
  const Accel accel = build_layout(scene, Builder::binned, Layout::bvh8);
  TraceOptions single;
  single.stream = false;
  single.packets = false;
  std::vector<Hit> want(rays.size()), want_any(rays.size());
  trace(accel, rays, want, false, single);
  trace(accel, rays, want_any, true, single);
  size_t hits = 0;
  for (const Hit& h : want) hits += h.hit();
  EXPECT_GT(hits, rays.size() / 20);
  for (int threads : {1, 2}) {
    ThreadLimit limit(threads);
    TraceOptions stream;
    stream.stream = true;
    std::vector<Hit> got(rays.size());
    trace(accel, rays, got, stream);
    std::vector<uint8_t> occ(rays.size());
    occluded(accel, rays, occ, stream);
    for (size_t i = 0; i < rays.size(); ++i) {
      ASSERT_EQ(got[i].prim_id, want[i].prim_id) << "ray " << i << " threads " << threads;
      ASSERT_EQ(float_bits(got[i].t), float_bits(want[i].t)) << "ray " << i;
      ASSERT_EQ(float_bits(got[i].u), float_bits(want[i].u)) << "ray " << i;
      ASSERT_EQ(bool(occ[i]), want_any[i].hit()) << "ray " << i;
    }
  }
}

// Ray streams (stream on, packets unset) where many rays share every list and hit shared
// edges and vertices exactly: ties at equal distance resolve to the smallest prim id as for
// single rays, closest and any hit, segments and tmin > 0 included.
TEST(StreamMode, RayStreamsResolveTiesAsSingleRays) {
  const Scene scene = test::closed_sphere(5, {0, 0, 0}, 1.0f);
  const std::vector<Vec3>& vertices = scene.meshes[0].positions;
  test::Rng rng{11};
  std::vector<Ray> rays;
  for (int i = 0; i < 40000; ++i) {
    const Vec3 target = vertices[size_t(rng.next() % vertices.size())];
    // Origins in a small cluster, so the lists stay long down the tree.
    const Vec3 o = Vec3{2.5f, 0.3f, -0.2f} + rng.on_sphere() * 0.05f;
    Ray r{o, target - o};
    if (i % 5 == 1) r.tmax = 0.9f;  // a segment that may stop short of the sphere
    if (i % 7 == 2) r.tmin = 0.5f;  // starts inside it: the far side
    rays.push_back(r);
  }
  const Accel accel = build_layout(scene, Builder::binned, Layout::bvh8);
  TraceOptions single, stream;
  single.stream = false;
  single.packets = false;
  stream.stream = true;
  for (Isa isa : test::supported_isas()) {
    single.isa = stream.isa = isa;
    std::vector<Hit> want(rays.size()), got(rays.size());
    trace(accel, rays, want, single);
    trace(accel, rays, got, stream);
    std::vector<uint8_t> want_occ(rays.size()), occ(rays.size());
    occluded(accel, rays, want_occ, single);
    occluded(accel, rays, occ, stream);
    size_t hits = 0;
    for (size_t i = 0; i < rays.size(); ++i) {
      ASSERT_EQ(got[i].prim_id, want[i].prim_id) << isa_name(isa) << " ray " << i;
      ASSERT_EQ(float_bits(got[i].t), float_bits(want[i].t)) << isa_name(isa) << " ray " << i;
      ASSERT_EQ(float_bits(got[i].u), float_bits(want[i].u)) << isa_name(isa) << " ray " << i;
      ASSERT_EQ(float_bits(got[i].v), float_bits(want[i].v)) << isa_name(isa) << " ray " << i;
      ASSERT_EQ(occ[i], want_occ[i]) << isa_name(isa) << " ray " << i;
      hits += got[i].hit();
    }
    EXPECT_GT(hits, rays.size() / 2);
  }
}

// Mid-size incoherent batches with the default options: the Accel times batches as ray streams
// and not (PacketChoice), then takes the faster; every batch gets the single-ray hits.
TEST(StreamMode, MidSizeBatchesTimedEachWayGetTheSameHits) {
  const Scene scene = test::random_soup(4000, 0.1f, 31);
  const std::vector<Ray> rays = test::random_rays(stream_trial_rays + 3000, 32);
  const Accel accel = build_layout(scene, Builder::binned, Layout::bvh8);
  TraceOptions single;
  single.stream = false;
  single.packets = false;
  std::vector<Hit> want(rays.size());
  trace(accel, rays, want, single);
  for (int round = 0; round < 6; ++round) {  // the first four are trials, two each way
    std::vector<Hit> got(rays.size());
    trace(accel, rays, got);
    for (size_t i = 0; i < rays.size(); ++i) {
      ASSERT_EQ(got[i].prim_id, want[i].prim_id) << "round " << round << " ray " << i;
      ASSERT_EQ(float_bits(got[i].t), float_bits(want[i].t)) << "round " << round << " ray " << i;
    }
  }
}

// More rays than one sort group holds: the second group's hits land in their own slots.
TEST(StreamMode, BatchesLargerThanOneGroup) {
  const Scene scene = test::random_soup(64, 0.3f, 4);
  const std::vector<Ray> rays = test::random_rays(stream_group + 40000, 6);
  const Accel accel = build_layout(scene, Builder::binned, Layout::bvh8);
  TraceOptions single, stream;
  single.stream = false;
  stream.stream = true;
  std::vector<Hit> want(rays.size()), got(rays.size());
  trace(accel, rays, want, single);
  trace(accel, rays, got, stream);
  size_t hits = 0;
  for (size_t i = 0; i < rays.size(); ++i) {
    ASSERT_EQ(got[i].prim_id, want[i].prim_id) << "ray " << i;
    ASSERT_EQ(float_bits(got[i].t), float_bits(want[i].t)) << "ray " << i;
    hits += got[i].hit();
  }
  EXPECT_GT(hits, rays.size() / 50);
}

TEST(StreamMode, OrderIsAPermutationGroupingOctants) {
  const std::vector<Ray> rays = test::random_rays(50000, 5);
  Bounds3 box{{-1, -1, -1}, {1, 1, 1}};
  RawArray<uint32_t> order;
  RawArray<uint64_t> scratch;
  stream_order(rays, box, order, scratch);
  ASSERT_EQ(order.size(), rays.size());
  std::vector<uint8_t> seen(rays.size());
  int octant_changes = 0, last = -1;
  for (uint32_t i : order) {
    ASSERT_LT(i, rays.size());
    ASSERT_FALSE(seen[i]) << "index " << i << " twice";
    seen[i] = 1;
    const Vec3& d = rays[i].dir;
    const int oct = std::signbit(d.x) | std::signbit(d.y) << 1 | std::signbit(d.z) << 2;
    octant_changes += oct != last;
    last = oct;
  }
  EXPECT_LE(octant_changes, 8);  // octant is the key's top field
}

}  // namespace
}  // namespace kestrel

TEST(StreamMode, PacketChoiceIsNotSteeredByOutlierTrials) {
  // The trials of the faster way (packets: 5 ns per ray) include a few that the thread was
  // preempted in or that ran on cold caches (hundreds of ns per ray); single rays take 8. A
  // running sum would pick single rays for a long while after such a trial; the choice must
  // still be packets, and must follow when the speeds change places.
  kestrel::PacketChoice choice;
  const auto trials = [&](double packets_ns, double single_ns, int outliers) {
    for (int k = 0; k < 15; ++k) {
      choice.done(true, uint64_t(1000 * (k < outliers ? 400.0 : packets_ns)), 1000);
      choice.done(false, uint64_t(1000 * single_ns), 1000);
    }
  };
  const auto picks_packets = [&] {
    int packets = 0, decided = 0;
    for (int k = 0; k < 64; ++k) {
      bool trial;
      const bool p = choice.next(trial);
      if (!trial) packets += p, ++decided;
    }
    return decided > 0 && packets == decided;
  };
  trials(5, 8, 3);
  EXPECT_TRUE(picks_packets());
  trials(9, 6, 0);  // single rays are now the faster way
  EXPECT_FALSE(picks_packets());
  choice.reset();
  choice.done(true, 400000, 1000);  // one cold trial each way: the slow one must not decide
  choice.done(false, 8000, 1000);
  trials(5, 8, 0);
  EXPECT_TRUE(picks_packets());
}
