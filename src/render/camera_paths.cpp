// A tile's camera rays and their paths' random number generators (TilePaths::begin): for a
// pinhole camera 16 pixels at a time in SIMD lanes (render/surface_rows.inl: the scalar code's
// bits), otherwise pixel by pixel.
#include <algorithm>
#include <cmath>

#include "render/renderer_impl.h"
#include "render/surface_rows.h"

namespace kestrel {

using namespace render;

void Renderer::Impl::camera_paths(const WavePass& wp, int x0, int y0, int x1, int y1,
                                  std::vector<Rng>& rngs, std::vector<Ray>& rays,
                                  std::vector<uint32_t>& active) {
  const RenderSettings& s = wp.s;
  const size_t count = size_t(x1 - x0) * size_t(y1 - y0);
  const int tw = x1 - x0, th = y1 - y0;
  // A pinhole camera's rays and their paths' generators in SIMD lanes, 16 pixels at a time
  // (the same bits); otherwise pixel by pixel.
  const CameraRowsKernel lanes = wp.rows && wp.cam.aperture <= 0 ? wp.rows->camera : nullptr;
  if (lanes) {
    rngs.resize(count, Rng::from_state(0, 1));  // every one set below
  } else {
    rngs.clear();
    rngs.reserve(count);
    for (size_t i = 0; i < count; ++i) {
      const int x = x0 + int(i % size_t(tw)), y = y0 + int(i / size_t(tw));
      const uint64_t pixel = uint64_t(y) * uint64_t(s.width) + uint64_t(x);
      rngs.emplace_back(s.seed, s.frame, pixel, uint64_t(wp.pass));
    }
  }
  constexpr int group = SurfaceRows::size;
  int gx[group], gy[group];
  uint64_t state[group], inc[group];
  float dx[group], dy[group], dz[group];
  const Vec3 basis[3] = {wp.cam.forward, wp.cam.right, wp.cam.up};
  CameraRowsArgs args;
  args.seed = s.seed, args.frame = s.frame, args.sample = uint64_t(wp.pass);
  args.image_width = s.width, args.x = gx, args.y = gy, args.jx = wp.jx, args.jy = wp.jy;
  args.basis = basis, args.tan_half = wp.cam.tan_half, args.aspect = wp.cam.aspect;
  args.width = wp.cam.width, args.height = wp.cam.height;
  args.state = state, args.inc = inc, args.dx = dx, args.dy = dy, args.dz = dz;
  int m = 0;
  const auto flush = [&](size_t end) {  // the group's m pixels, paths end - m .. end - 1
    args.n = size_t(m);
    lanes(args);
    for (int j = 0; j < m; ++j) {
      const size_t k = end - size_t(m) + size_t(j);
      rngs[active[k]] = Rng::from_state(state[j], inc[j]);
      rays[k] = Ray{wp.cam.eye, Vec3{dx[j], dy[j], dz[j]}, 0.0f, INFINITY};
    }
    m = 0;
  };
  // The camera rays in 4 x 4 blocks of pixels (row-major within a block and over the blocks),
  // so that a packet of 16 consecutive rays is a square of the image, not half a row: a
  // narrower frustum. Path k of the first bounce is pixel active[k].
  size_t k = 0;
  for (int by = 0; by < th; by += 4)
    for (int bx = 0; bx < tw; bx += 4)
      for (int y = by; y < std::min(by + 4, th); ++y)
        for (int x = bx; x < std::min(bx + 4, tw); ++x, ++k) {
          const size_t i = size_t(y) * size_t(tw) + size_t(x);
          active[k] = uint32_t(i);
          if (lanes) {
            gx[m] = x0 + x, gy[m] = y0 + y;
            if (++m == group) flush(k + 1);
            continue;
          }
          Rng& rng = rngs[i];
          const float lu = rng.uniform(), lv = rng.uniform();
          rays[k] = wp.cam.ray(float(x0 + x) + wp.jx, float(y0 + y) + wp.jy, lu, lv);
        }
  if (m > 0) flush(k);
}

}  // namespace kestrel
