// Embree 3 as the side-by-side peer: same triangles, same global prim ids, same rays.
// Used only by benchmarks and differential tests, never by the library.
#pragma once
#include <memory>
#include <span>
#include <string>

#include "kestrel/trace.h"

namespace kestrel::peer {

/// Embree's build qualities (RTC_BUILD_QUALITY_LOW / MEDIUM / HIGH / REFIT: the geometry's
/// BVH is refitted, not rebuilt, when its vertices change).
enum class EmbreeQuality { low, medium, high, refit };
const char* embree_quality_name(EmbreeQuality q);

/// An Embree device + scene over the valid triangles of a kestrel scene (invalid triangles
/// become degenerate (0,0,0) triangles, which Embree skips, so prim ids stay global).
class EmbreeScene {
 public:
  /// threads = 0: Embree's default pool; 1 for single-thread figures.
  EmbreeScene(const Scene& scene, EmbreeQuality quality, int threads);
  ~EmbreeScene();
  EmbreeScene(const EmbreeScene&) = delete;
  EmbreeScene& operator=(const EmbreeScene&) = delete;

  /// Builds (rtcCommitScene) again from scratch and returns its wall time in ms.
  double rebuild();
  double last_build_ms() const;
  /// New vertex positions (every mesh's, concatenated in scene order), then rtcCommitScene:
  /// a refit for EmbreeQuality::refit. Returns rtcCommitScene's wall time in ms.
  double update_vertices(std::span<const Vec3> positions);
  Hit intersect(const Ray& ray) const;
  /// Any hit: t is set to tmax's hit marker (Embree reports no distance for occlusion):
  /// returns a Hit whose prim_id is 0 (not a real id) when occluded, else a miss.
  bool occluded(const Ray& ray) const;
  /// Batches, one rtcIntersect1 / rtcOccluded1 per ray (one intersect context per batch).
  void intersect(std::span<const Ray> rays, std::span<Hit> hits) const;
  void occluded(std::span<const Ray> rays, std::span<uint8_t> occluded) const;
  /// Closest hits through rtcIntersect16 (packets of 16 consecutive rays, SoA).
  void intersect16(std::span<const Ray> rays, std::span<Hit> hits) const;
  /// Embree's memory for this scene's BVH (rtcGetSceneBounds does not expose it; we use
  /// the device memory monitor), bytes.
  size_t memory_bytes() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

/// Embree's version string, e.g. "3.13.5".
std::string embree_version();

}  // namespace kestrel::peer
