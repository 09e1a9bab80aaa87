// A world-space radiance cache for the real-time loop (RenderSettings::radiance_cache; biased,
// off by default): the outgoing radiance of the surfaces that camera paths reach after their
// first bounce, averaged over a hash grid of cells and over frames, so that most paths can
// stop there instead of tracing every further bounce (the idea of Müller et al. 2021's
// radiance caching and of spatial-hash caches such as NVIDIA's SHaRC; written here).
//
// Cells are cubes whose edge is a power of two about `cell_pixels` pixels wide at the cell's
// distance from the camera, split by the dominant axis of the geometric normal (so the two
// faces of a wall never share a cell). Each cell keeps a mean and a sample count; a pass's
// samples are merged after the pass in tile order, so the cache (and every image that reads
// it) does not depend on the thread count.
#pragma once
#include <cstdint>
#include <span>
#include <vector>

#include "core/vec.h"

namespace kestrel::render {

/// One sample of a cell: the outgoing radiance a path measured at a surface in it.
struct CacheRecord {
  uint64_t key;
  Vec3 radiance;
};

class RadianceCache {
 public:
  static constexpr float cell_pixels = 8;       ///< cell edge, in pixels at its distance
  static constexpr float max_samples = 128;     ///< a cell's history, in samples
  static constexpr float min_samples = 4;       ///< a cell answers once it has this many
  static constexpr uint32_t half_life = 16;     ///< passes after which the history weighs half
  static constexpr uint32_t max_age = 64;       ///< passes without a sample before eviction
  static constexpr size_t capacity = 1u << 17;  ///< cells (open addressing; 10 MB in all)
  /// New cells are refused beyond half the capacity; an eviction runs every 16 passes, and
  /// as soon as this many cells live ...
  static constexpr size_t evict_at = capacity / 2 - capacity / 32;
  /// ... when it keeps at most this many: the most recently sampled (a table full of cells
  /// younger than max_age would otherwise refuse new cells and evict nothing pass after pass).
  static constexpr size_t keep_at = capacity * 3 / 8;

  /// The camera the cells are sized for: its eye and the angle one pixel subtends.
  void set_view(Vec3 eye, float pixel_angle) { eye_ = eye, pixel_angle_ = pixel_angle; }
  /// The cell of point p whose geometric normal is ng: its key (never 0) and edge length.
  struct Cell {
    uint64_t key;
    float size;
  };
  Cell cell(Vec3 p, Vec3 ng) const;
  /// The cell's mean, when it has at least min_samples.
  bool lookup(uint64_t key, Vec3& radiance) const;
  /// Starts loading the slot where lookup(key) begins.
  void prefetch(uint64_t key) const {
    if (!cells_.empty()) __builtin_prefetch(&cells_[key & (capacity - 1)]);
  }
  /// Adds a pass's samples (call in a fixed order), then end_pass() blends them in.
  void add(std::span<const CacheRecord> records);
  void end_pass();
  void clear();
  size_t cells() const { return live_; }

 private:
  struct Slot {
    uint64_t key = 0;  // 0: empty
    Vec3 mean{0, 0, 0};
    float samples = 0;
    uint32_t last = 0;  // the pass of its last sample
  };
  struct Pending {
    Vec3 sum{0, 0, 0};
    uint32_t count = 0;
  };
  size_t find(uint64_t key) const;  // its slot, or capacity
  size_t insert(uint64_t key);      // its slot (new or found), or capacity when full
  void evict();                     // drops cells older than max_age, rehashing the rest
  std::vector<Slot> cells_;
  std::vector<Slot> spare_;  // evict()'s new table, kept between evictions (no page faults)
  std::vector<Pending> pending_;
  std::vector<uint32_t> touched_;  // slots with pending samples, in order of first touch
  size_t live_ = 0;
  uint32_t pass_ = 0;
  Vec3 eye_{0, 0, 0};
  float pixel_angle_ = 0;
};

}  // namespace kestrel::render
