// Closest-hit and any-hit queries over an Accel: the scalar Bvh2 reference, the dispatch to
// the wide SIMD kernels (chosen once from the CPU's features), batches, and brute force.
#include <fmt/format.h>

#include <atomic>
#include <cmath>
#include <cstdlib>
#include <optional>

#include "core/parallel.h"
#include "core/raw_array.h"
#include "geometry/triangle_intersect.h"
#include "kestrel/error.h"
#include "traverse/accel_nodes.h"
#include "traverse/batches.h"
#include "traverse/kernels.h"
#include "traverse/stream.h"
#include "traverse/traverse_bvh2.h"

namespace kestrel {

// ---- kernels per instruction set (kestrel/isa.h chooses) ---------------------------------

const kernels::Table& kernels::table_for(Isa isa) {
  switch (isa) {
    case Isa::avx512:
      return table_avx512();
    case Isa::avx2:
      return table_avx2();
    default:
      return table_sse2();
  }
}

// ---- scalar Bvh2 reference ----------------------------------------------------------------

namespace {
template <bool AnyHit>
Hit intersect_bvh2(const Accel& accel, const Ray& ray) {
  Hit hit;
  if (!is_traceable(ray)) return hit;
  const WatertightRay wr(ray);
  float tmax = ray.tmax;
  const Triangle* tris = accel.nodes->triangles.data();
  const uint32_t* ids = accel.nodes->bvh.prim_ids.data();
  uint32_t best = invalid_id;
  traverse_bvh2<AnyHit>(accel.nodes->bvh, ray, tmax, [&](uint32_t first, uint32_t count, float& t) {
    for (uint32_t i = first; i < first + count; ++i) {
      float tc, uc, vc;
      if (!watertight_hit(wr, tris[i], ray.tmin, tc, uc, vc)) continue;
      if (AnyHit ? tc < t : closer_hit(tc, ids[i], t, best)) {
        t = tc;
        best = ids[i];
        hit.u = uc;
        hit.v = vc;
        if constexpr (AnyHit) return true;
      }
    }
    return false;
  });
  if (best != invalid_id) {
    hit.t = tmax;
    hit.prim_id = best;
  } else {
    hit.u = hit.v = 0;
  }
  return hit;
}

// Single-ray occlusion visits a node's children in slot order (largest box first) or nearest
// first. Neither wins everywhere (2026-12-06, shadow rays towards a point light, kestrel ÷
// rtcOccluded1: the soup 0.87 slot order against 0.99-1.02 nearest first, its occluders near
// the rays' origins; the sphere field 1.07 against 0.78-0.80, its occluders the large
// spheres), so the Accel times chunks both ways (PacketChoice) and takes the faster, apart for
// segments (finite tmax) and rays; the answers are the same either way.
template <class Fn>
void any_hit_order(const Accel& accel, std::span<const Ray> rays, Fn&& traced) {
  if (rays.size() < 16) return traced(false);  // single queries (intersect_any): untimed
  const bool segments = std::isfinite(rays[0].tmax);
  accel.nodes->choices->any_order[segments ? 0 : 1].run(rays.size(), traced);
}

// A wide layout's kernels (kernels::Table's, for Bvh4Fn or Bvh8Fn).
template <class Fn>
struct WideFns {
  Fn closest, any, any_nearest, packet, any_packet;
};

// The traceable runs of `rays` through one wide tree's kernels: packets or single rays as
// asked, and single-ray occlusion in the order any_hit_order picks.
template <class Bvh, class Fn>
void trace_wide(const Accel& accel, const Bvh& bvh, std::span<const Ray> rays, std::span<Hit> hits,
                bool any_hit, bool packets, const WideFns<Fn>& f) {
  // The kernels give untraceable rays a miss themselves (kernels.h).
  const auto run = [&](Fn fn) {
    fn(bvh.nodes.data(), bvh.blocks.data(), rays.data(), hits.data(), rays.size());
  };
  if (any_hit && !packets)
    return any_hit_order(accel, rays, [&](bool nearest) { run(nearest ? f.any_nearest : f.any); });
  run(any_hit ? f.any_packet : packets ? f.packet : f.closest);
}

void trace_range(const Accel& accel, std::span<const Ray> rays, std::span<Hit> hits, bool any_hit,
                 const kernels::Table& k, bool packets) {
  switch (accel.layout) {
    case Layout::bvh4:
      if (accel.nodes->bvh4.empty()) break;
      return trace_wide(
          accel, accel.nodes->bvh4, rays, hits, any_hit, packets,
          WideFns<kernels::Bvh4Fn>{k.closest4, k.any4, k.any_nearest4, k.packet4, k.any_packet4});
    case Layout::bvh8:
      if (accel.nodes->bvh8.empty()) break;
      return trace_wide(
          accel, accel.nodes->bvh8, rays, hits, any_hit, packets,
          WideFns<kernels::Bvh8Fn>{k.closest8, k.any8, k.any_nearest8, k.packet8, k.any_packet8});
    default:
      if (any_hit) {
        for (size_t i = 0; i < rays.size(); ++i) hits[i] = intersect_bvh2<true>(accel, rays[i]);
      } else {
        for (size_t i = 0; i < rays.size(); ++i) hits[i] = intersect_bvh2<false>(accel, rays[i]);
      }
      return;
  }
  for (Hit& h : hits) h = Hit{};  // empty wide BVH
}

// Whether closest hits over `accel` with `isa` can go as ray streams (kernels' stream8).
bool has_ray_streams(const Accel& accel, Isa isa) {
  return accel.layout == Layout::bvh8 && isa != Isa::sse2;
}

// Stream mode: the hits of each sorted chunk written back to the caller's slots. Queries over
// 8-wide nodes with AVX2 or AVX-512 go as ray streams of ray_stream_rays rays
// (wide_stream_lanes.inl) unless the caller chose packets or single rays; otherwise each
// chunk goes as packets or single rays by PacketChoice (stream.h).
void trace_stream(const Accel& accel, std::span<const Ray> rays, bool any_hit, Isa isa,
                  const kernels::Table& k, std::optional<bool> packets,
                  FunctionRef<void(size_t caller, const Hit& hit)> put,
                  FunctionRef<void(size_t caller)> prefetch_put) {
  const auto write_back = [&](const uint32_t* callers, const Hit* local, size_t n) {
    for (size_t j = 0; j < n; ++j) {
      if (j + 16 < n) prefetch_put(callers[j + 16]);
      put(callers[j], local[j]);
    }
  };
  if (!packets && has_ray_streams(accel, isa)) {
    const kernels::Bvh8Fn fn = any_hit ? k.any_stream8 : k.stream8;
    const Bvh8& bvh = accel.nodes->bvh8;
    for_each_stream_chunk(
        rays, accel.bounds,
        [&](const Ray* r, const uint32_t* callers, size_t n) {
          RawArray<Hit> local(n);
          kernels::for_each_traceable_run(std::span<const Ray>(r, n), local.data(),
                                          [&](const Ray* rr, Hit* h, size_t m) {
                                            fn(bvh.nodes.data(), bvh.blocks.data(), rr, h, m);
                                          });
          write_back(callers, local.data(), n);
        },
        ray_stream_rays);
    return;
  }
  PacketChoice choice(packets);
  for_each_stream_chunk(rays, accel.bounds, [&](const Ray* r, const uint32_t* callers, size_t n) {
    Hit local[stream_chunk];
    choice.run(n, [&](bool packets) {
      trace_range(accel, std::span<const Ray>(r, n), std::span(local, n), any_hit, k, packets);
    });
    write_back(callers, local, n);
  });
}

bool use_stream(const Accel& accel, std::span<const Ray> rays, bool any_hit, Isa isa,
                const TraceOptions& options) {
  return accel.layout != Layout::bvh2 &&
         stream_by_default(rays, accel.bounds, accel.memory_bytes(), any_hit,
                           has_ray_streams(accel, isa), options);
}

// Incoherent batches of >= stream_trial_rays rays that stream_by_default does not stream
// (closest hit, ray streams available, neither option set: smaller or in pixel order): ray
// streams win where the scene keeps many rays on each node and lose where they part (one
// thread: Sponza's 908 k bounces in pixel order 3.9 -> 5.9 Mrays/s as streams, its 227 k at
// 640x360 3.2-3.3 -> 4.1-5.4; the terrain's 543 k in pixel order 5.9 -> 4.4, the soup's 190 k
// 1.7-1.9 -> 1.5, the bunny grid's 90 k 2.6-2.7 -> 1.5), so the Accel times batches each way
// (PacketChoice) and takes the faster. Called after use_stream said no.
bool may_stream(const Accel& accel, std::span<const Ray> rays, bool any_hit, Isa isa,
                const TraceOptions& options) {
  return !any_hit && !options.stream && !options.packets && has_ray_streams(accel, isa) &&
         rays.size() >= stream_trial_rays && !looks_coherent(rays);
}

// Traces a run of rays (traced(packets)) as packets where asked or, unsaid, where the run looks
// coherent and the Accel's PacketChoice finds packets faster so far (some runs are timed each
// way: a wide tree's packets lose to single rays where the triangles are small in the image,
// e.g. the bunny grid's camera rays at 640x360, 0.7x).
template <class Fn>
void traced_as(const Accel& accel, std::span<const Ray> rays, const TraceOptions& options,
               bool any_hit, Fn&& traced) {
  (any_hit ? accel.nodes->choices->any : accel.nodes->choices->closest)
      .run(
          options.packets, [&] { return accel.layout != Layout::bvh2 && looks_coherent(rays); },
          rays.size(), traced);
}

void check_sizes(size_t rays, size_t out) {
  if (rays != out)
    throw Error(ErrorCode::invalid_argument,
                fmt::format("trace: {} rays but room for {} results", rays, out));
}
}  // namespace

Hit intersect(const Accel& accel, const Ray& ray) {
  Hit hit;
  trace_range(accel, std::span(&ray, 1), std::span(&hit, 1), false,
              kernels::table_for(default_isa()), false);
  return hit;
}

Hit intersect_any(const Accel& accel, const Ray& ray) {
  Hit hit;
  trace_range(accel, std::span(&ray, 1), std::span(&hit, 1), true,
              kernels::table_for(default_isa()), false);
  return hit;
}

void trace(const Accel& accel, std::span<const Ray> rays, std::span<Hit> hits, bool any_hit,
           const TraceOptions& options) {
  check_sizes(rays.size(), hits.size());
  const Isa isa = options.isa.value_or(default_isa());
  require_supported(isa);
  const kernels::Table& k = kernels::table_for(isa);
  const auto streamed = [&] {
    trace_stream(
        accel, rays, any_hit, isa, k, options.packets, [&](size_t i, const Hit& h) { hits[i] = h; },
        [&](size_t i) { __builtin_prefetch(&hits[i], 1); });
  };
  const auto unstreamed = [&] {
    parallel_for(0, rays.size(), 1024, [&](size_t b, size_t e) {
      const auto chunk = rays.subspan(b, e - b);
      traced_as(accel, chunk, options, any_hit, [&](bool packets) {
        trace_range(accel, chunk, hits.subspan(b, e - b), any_hit, k, packets);
      });
    });
  };
  if (use_stream(accel, rays, any_hit, isa, options)) return streamed();
  if (may_stream(accel, rays, any_hit, isa, options))
    return accel.nodes->choices->stream.run(rays.size(),
                                            [&](bool s) { s ? streamed() : unstreamed(); });
  unstreamed();
}

void trace(const Accel& accel, std::span<const Ray> rays, std::span<Hit> hits,
           const TraceOptions& options) {
  trace(accel, rays, hits, false, options);
}

void occluded(const Accel& accel, std::span<const Ray> rays, std::span<uint8_t> out,
              const TraceOptions& options) {
  check_sizes(rays.size(), out.size());
  const Isa isa = options.isa.value_or(default_isa());
  require_supported(isa);
  const kernels::Table& k = kernels::table_for(isa);
  if (use_stream(accel, rays, true, isa, options)) {
    trace_stream(
        accel, rays, true, isa, k, options.packets,
        [&](size_t i, const Hit& h) { out[i] = h.hit(); },
        [&](size_t i) { __builtin_prefetch(&out[i], 1); });
    return;
  }
  parallel_for(0, rays.size(), 1024, [&](size_t b, size_t e) {
    Hit local[256];
    for (size_t i = b; i < e; i += 256) {
      const size_t n = std::min<size_t>(256, e - i);
      const auto chunk = rays.subspan(i, n);
      traced_as(accel, chunk, options, true, [&](bool packets) {
        trace_range(accel, chunk, std::span(local, n), true, k, packets);
      });
      for (size_t j = 0; j < n; ++j) out[i + j] = local[j].hit();
    }
  });
}

Hit intersect_brute_force(std::span<const Triangle> triangles, std::span<const uint8_t> valid,
                          const Ray& ray, bool any_hit) {
  Hit hit;
  if (!is_traceable(ray)) return hit;
  const WatertightRay wr(ray);
  float t = ray.tmax;
  for (size_t i = 0; i < triangles.size(); ++i) {
    if (!valid.empty() && !valid[i]) continue;
    float tc, uc, vc;
    if (watertight_hit(wr, triangles[i], ray.tmin, tc, uc, vc) && tc < t) {
      t = tc;
      hit = {tc, uint32_t(i), uc, vc};
      if (any_hit) break;
    }
  }
  return hit;
}

}  // namespace kestrel
