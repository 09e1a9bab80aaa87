// Benchmark and test hooks of the renderer (internal): record every ray batch a render traces,
// and trace them again alone (bench/render_bench.cpp: in-render against raw ray throughput);
// the number of tiles traced together.
#pragma once
#include <array>
#include <cstddef>
#include <cstdint>
#include <vector>

#include "kestrel/render.h"

namespace kestrel {

/// Every ray batch a render traced, in order.
struct RayCapture {
  std::vector<Ray> camera, bounce, shadow;
  std::vector<size_t> camera_batches, bounce_batches, shadow_batches;  ///< batch sizes
};

struct RendererTesting {
  /// The next renders record every ray batch into `capture` (and run on one thread);
  /// nullptr stops recording.
  static void set_capture(Renderer& renderer, RayCapture* capture);
  /// Traces captured batches again, alone, with the same batch sizes: ms for camera,
  /// bounce and shadow rays.
  static std::array<double, 3> retrace(const Renderer& renderer, const RayCapture& capture);
  /// Tiles per wave (each bounce of a wave's tiles one batch); the default is
  /// render::wave_tiles. The image is the same for any value.
  static void set_wave_tiles(Renderer& renderer, size_t tiles);
  /// Whether the shading computes hits' surfaces, and a tile's pinhole camera rays with their
  /// paths' generators, in SIMD rows where it can (the default) or one by one (surface_at,
  /// CameraModel::ray): the image is the same either way.
  static void set_surface_rows(Renderer& renderer, bool on);
  /// ReSTIR's target function (the branch-light form the candidates use) against the
  /// luminance of its full evaluation, at n random surfaces (shading normals tilted off the
  /// geometric ones, views below them too, random materials) and random light samples of the
  /// renderer's lights (after a render): {samples whose two values differ, samples with a
  /// positive target}.
  static std::array<size_t, 2> restir_target_check(const Renderer& renderer, int n, uint64_t seed);
};

}  // namespace kestrel
