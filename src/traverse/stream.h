// Stream mode for large incoherent batches: rays are traced in an order that groups similar
// ones (Pharr et al. 1997; Eisenacher et al. 2013 sort by direction and origin), as ray
// streams (wide_stream_lanes.inl) or as packets or single rays, and every hit is written back
// to its caller's slot. Hits are the ones single rays
// get: each ray's traversal is exact and independent of its packet mates.
//
// The order is global within groups of up to 2^20 rays: a stable LSD radix sort (8-bit
// digits, so the scatter's 256 streams stay within the TLB) of 40-bit keys - direction octant,
// origin (5 bits per axis, Morton order, within the scene's box), direction (5 + 5 bits of
// the octahedral |x|, |y|), then origin again (4 more bits per axis) - each packed with the
// ray's index. Sorting only within windows of 4-16 k consecutive rays was tried and gained
// nothing on Sponza's diffuse rays: too few rays share a cell there. Measured there (900 k
// rays, one thread): ordering ~50 ms, the random gather and write-back ~70 ms, tracing the
// sorted rays as packets ~240 ms against ~420 ms for the caller's order. Whether the sorted
// chunks go as packets or single rays is timed as the stream runs (trace.cpp: trace_stream).
#pragma once
#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdint>
#include <mutex>
#include <optional>
#include <span>

#include "core/parallel.h"
#include "core/raw_array.h"
#include "kestrel/trace.h"

namespace kestrel {

inline constexpr size_t stream_group = size_t(1) << 20;

/// The default takes the stream for closest-hit batches of at least this many incoherent rays
/// (trace.cpp: use_stream); where it traces sorted packets (no ray streams for the layout or
/// ISA), only for unordered rays over a tree of at least this many bytes: larger than a core's
/// L2 cache (1-2 MB), where the order pays. (It was 4 MB until the SAH-optimal
/// collapse shrank Sponza's tree from 4.26 to 4.00 MB: its shuffled bounces then went
/// unsorted, 4.05 -> 3.29 Mrays/s, against 4.34 sorted.)
inline constexpr size_t stream_min_rays = size_t(1) << 18;
/// Other incoherent batches of at least this many rays (smaller, or in pixel order) go as ray
/// streams where timed batches find them faster (trace.cpp: may_stream).
inline constexpr size_t stream_trial_rays = size_t(1) << 16;
inline constexpr size_t stream_min_accel_bytes = size_t(2) << 20;

/// Rays per chunk the stream driver hands to its caller (a stack buffer of hits fits).
inline constexpr size_t stream_chunk = 256;

/// Rays per ray stream (kernels' stream8: closest hit, 8-wide nodes, AVX2 or AVX-512): a
/// chunk of the ordered batch walks the tree together. Inside Sponza (908 k shuffled
/// diffuse rays, one thread) 8 k, 16 k and 32 k rays per stream traced at 5.90, 5.96 and
/// 5.86 Mrays/s, 128 k at 5.56.
inline constexpr size_t ray_stream_rays = 16384;

/// Packets or single rays for chunks of a batch (or of many batches: an Accel keeps one per
/// query kind, an InstancedScene too between BLAS rebuilds): where the caller did not say, two
/// chunks in every 32 are traced one each way and timed (in every 256 or 1 024 once each way
/// was timed 8 times and one is 1.3x or 2x faster), and the rest go the way whose recent trials
/// were faster per ray (the lower quartile of each way's last 15; the hits are the same either
/// way). Sorted bounces inside a room (short, between near walls) trace faster as packets,
/// those of an open scene (long rays that part) as single rays: measured with either fixed,
/// one thread, Sponza's shuffled diffuse rays 3.4-3.8 (packets) against 2.8-3.2 Mrays/s, the
/// sphere field's 3.3 against 4.0, the bunny grid's at 3840x2160 2.5 against 3.3. Camera rays
/// through instances: the glTF samples' 1.7-1.9x faster as packets, the bunny grid's (16
/// instances of 69 k small triangles) 0.8x.
class PacketChoice {
 public:
  explicit PacketChoice(std::optional<bool> fixed = std::nullopt) : fixed_(fixed) {}
  /// Choices per whole batch (few, large, the first on cold caches): the first `warmup` calls
  /// alternate as trials and each way's first timing is not counted; later, two trials in
  /// every `period` calls (where one way is 1.3x or 2x faster: 8 or 32 times as few).
  PacketChoice(int warmup, bool drop_first, uint32_t period = 32)
      : warmup_(uint32_t(warmup)), period_(period), drop_first_(drop_first) {}

  /// Whether the next chunk goes as packets; `trial`: time it and report to done().
  bool next(bool& trial) {
    trial = false;
    if (fixed_) return *fixed_;
    const uint32_t t = started_.fetch_add(1, std::memory_order_relaxed);
    const float single = rate_[0].load(std::memory_order_relaxed),
                packet = rate_[1].load(std::memory_order_relaxed);
    // Trials of the slower way cost the most where it is much slower (Sponza's camera rays as
    // single rays: 4x): the clearer the difference, the rarer they are.
    // (Only once each way has been timed a few times: a first chunk that runs on cold caches
    // must not settle it.)
    uint32_t period = period_;
    if (trials_[0].load(std::memory_order_relaxed) >= 8 &&
        trials_[1].load(std::memory_order_relaxed) >= 8 && single > 0 && packet > 0) {
      const float ratio = packet / single;
      const float slower = ratio > 1 ? ratio : 1 / ratio;
      period = slower > 2.0f ? 32 * period_ : slower > 1.3f ? 8 * period_ : period_;
    }
    if (t < warmup_ || t % period < 2) return trial = true, (t & 1) != 0;
    return single == 0 || packet == 0 || packet <= single;  // packets' ns per ray <= singles'
  }
  void done(bool packets, uint64_t ns, size_t rays) {
    if (drop_first_ && first_[packets].exchange(false, std::memory_order_relaxed)) return;
    if (rays == 0) return;
    trials_[packets].fetch_add(1, std::memory_order_relaxed);
    // Each way's rate is the lower quartile of its last trials: a trial the thread was
    // preempted in, or that ran on cold caches, only ever takes longer, and must not steer the
    // choice (as a running sum it did, for the rest of a run: the Lamborghini's camera rays
    // traced as single rays, 1.6x slower, in about half the runs of `kestrel run`).
    const std::lock_guard lock(mutex_);
    Recent& r = recent_[packets];
    r.rate[r.next++ % Recent::size] = float(double(ns) / double(rays));
    const size_t n = std::min<size_t>(r.next, Recent::size);
    float sorted[Recent::size];
    std::copy(r.rate, r.rate + n, sorted);
    std::nth_element(sorted, sorted + n / 4, sorted + n);
    rate_[packets].store(sorted[n / 4], std::memory_order_relaxed);
  }
  /// Runs traced(packets) for the next chunk of `rays` rays the way next() says, timing it
  /// for done() when it is a trial.
  template <class Fn>
  void run(size_t rays, Fn&& traced) {
    bool trial;
    const bool packets = next(trial);
    if (!trial) return traced(packets);
    const auto start = std::chrono::steady_clock::now();
    traced(packets);
    done(packets,
         uint64_t(std::chrono::duration_cast<std::chrono::nanoseconds>(
                      std::chrono::steady_clock::now() - start)
                      .count()),
         rays);
  }
  /// The same for a caller's chunk: as `fixed` says when set (TraceOptions::packets), single
  /// rays where the chunk is no candidate for packets (candidate(), asked only when `fixed`
  /// is unset: it reads the rays), else as above.
  template <class Candidate, class Fn>
  void run(std::optional<bool> fixed, Candidate&& candidate, size_t rays, Fn&& traced) {
    if (fixed) return traced(*fixed);
    if (!candidate()) return traced(false);
    run(rays, traced);
  }
  /// Forgets what was measured (the scene changed).
  void reset() {
    const std::lock_guard lock(mutex_);
    started_ = 0;
    for (int k = 0; k < 2; ++k) rate_[k] = 0, trials_[k] = 0, first_[k] = true, recent_[k] = {};
  }

 private:
  std::optional<bool> fixed_;
  uint32_t warmup_ = 2, period_ = 32;
  bool drop_first_ = false;
  std::atomic<bool> first_[2] = {true, true};
  std::atomic<uint32_t> started_{0};
  std::atomic<float> rate_[2] = {0.0f, 0.0f};  // ns per ray, [0] single rays, [1] packets
  std::atomic<uint32_t> trials_[2] = {0, 0};   // chunks timed each way
  struct Recent {                              // each way's last trials (ns per ray)
    static constexpr size_t size = 15;
    float rate[size] = {};
    size_t next = 0;
  };
  std::mutex mutex_;
  Recent recent_[2];
};

namespace detail {
/// What an Accel has learnt of its coherent batches (AccelNodes::choices).
struct PacketChoices {
  PacketChoice closest, any;
  /// Incoherent batches the default does not stream: ray streams (true) or not (trace.cpp:
  /// may_stream). A renderer gives one or two such batches a frame: eight alternate first (the
  /// first each way not counted), then two in every 16 (with four, one timing each way settled
  /// the choice: inside Sponza the loop's first bounces went the slower way, 18.5-19.7 against
  /// 16.1-16.7 ms a frame, in half the runs).
  PacketChoice stream{8, true, 16};
  /// Single-ray any hit: children nearest first (true) or in slot order, for rays with a
  /// finite tmax ([0]: segments, e.g. towards a point light) and without ([1]) (trace.cpp:
  /// any_hit_order).
  PacketChoice any_order[2];
};
}  // namespace detail

/// Whether a batch looks coherent (camera rays, shadow rays towards one light): groups of 8
/// consecutive rays whose directions share signs and dominant axis, in 3 of 4 sampled groups
/// (one every 64 rays, at most coherent_samples spread over the batch).
bool looks_coherent(std::span<const Ray> rays);
inline constexpr size_t coherent_samples = 256;

/// TraceOptions::stream's default for a batch over a tree of `tree_bytes` bounded by `box`:
/// closest hit, `packets` unset, >= stream_min_rays rays, not coherent, consecutive origins far
/// apart (unordered), and a tree of >= stream_min_accel_bytes unless the kernels have ray
/// streams for it (`ray_streams`). An explicit option wins. (Where this says no, trace.cpp may
/// still time ray streams against the rest: may_stream.)
bool stream_by_default(std::span<const Ray> rays, const Bounds3& box, size_t tree_bytes,
                       bool any_hit, bool ray_streams, const TraceOptions& options);

/// The stream driver: orders each group of the batch (stream_order), gathers chunks of up
/// to stream_chunk rays in that order and calls chunk(rays, callers, n), which traces
/// rays[0, n) and writes hit j to the caller's slot callers[j]. Chunks run in parallel.
void for_each_stream_chunk(
    std::span<const Ray> rays, const Bounds3& box,
    FunctionRef<void(const Ray* rays, const uint32_t* callers, size_t n)> chunk,
    size_t chunk_rays = stream_chunk);

/// The trace order of a group (at most stream_group rays): order[i] = caller's index.
/// `scratch` is reused between calls.
void stream_order(std::span<const Ray> rays, const Bounds3& box, RawArray<uint32_t>& order,
                  RawArray<uint64_t>& scratch);

}  // namespace kestrel
