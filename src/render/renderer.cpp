// The Renderer: scene sync (materials, transforms, lights as of the scene's last commit),
// passes over tiles on the thread pool, the frame's AOVs as means of the samples, render
// of chosen tiles (distributed rendering), ray capture and retrace for benchmarks.
#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <cstdio>

#include "core/parallel.h"
#include "kestrel/error.h"
#include "kestrel/parallel.h"
#include "render/renderer_impl.h"

namespace kestrel {

using namespace render;

// ---- the renderer ------------------------------------------------------------------------------

Renderer::Renderer(const InstancedScene& scene, std::optional<Environment> environment)
    : impl_(new Impl) {
  Impl& r = *impl_;
  r.scene = &scene;
  const ValidationReport report = scene.validation();
  if (report.valid_triangle_count == 0)
    throw Error(ErrorCode::invalid_geometry,
                fmt::format("{}: no valid triangle to render ({})", r.source(), report.summary()));
  r.sync();  // the first sync: every previous transform is the current one
  r.choose_environment(std::move(environment));
}

Renderer::~Renderer() = default;
Renderer::Renderer(Renderer&&) noexcept = default;
Renderer& Renderer::operator=(Renderer&&) noexcept = default;

std::string Renderer::Impl::source() const {
  return scene->source().empty() ? "the scene" : scene->source();
}

// The scene's materials, transforms and lights as of its last commit; the transforms seen at
// the previous sync become the previous frame's (motion vectors).
void Renderer::Impl::sync() {
  const InstancedScene& s = *scene;
  generation = s.generation();
  materials = s.materials();
  const size_t given = materials.size();
  check_materials(source());
  std::vector<InstanceShade> old = std::move(instances);
  instances.assign(s.instance_capacity(), InstanceShade{});
  for (InstanceId i = 0; i < s.instance_capacity(); ++i) {
    if (!s.has_instance(i)) continue;
    InstanceShade& is = instances[i];
    is.mesh = &s.mesh(s.instance_mesh(i));
    const TriangleMesh& m = *is.mesh;
    is.colors = !m.colors.empty() && m.colors.size() == m.positions.size();
    if (!m.material_ids.empty() && m.material_ids.size() != m.triangle_count())
      throw Error(ErrorCode::invalid_argument,
                  fmt::format("{}: mesh '{}' has {} material ids for {} triangles", source(),
                              m.name, m.material_ids.size(), m.triangle_count()));
    for (uint32_t id : m.material_ids)
      if (id >= given)
        throw Error(
            ErrorCode::invalid_argument,
            fmt::format("{}: mesh '{}' names material {} of {}", source(), m.name, id, given));
    is.xf = s.transform(i);
    is.prev_xf = i < old.size() && old[i].mesh ? old[i].xf : is.xf;
    const Affine3 identity;
    is.identity =
        std::equal(std::begin(is.xf.m), std::end(is.xf.m), std::begin(identity.m)) &&
        std::equal(std::begin(is.prev_xf.m), std::end(is.prev_xf.m), std::begin(identity.m));
    const Affine3 inv = inverse(is.xf);
    // inverse transpose of the linear part: row r of the result = column r of inv
    for (int row = 0; row < 3; ++row)
      for (int col = 0; col < 3; ++col) is.nrm[row * 3 + col] = inv.m[col * 4 + row];
  }
  cutouts = std::any_of(materials.begin(), materials.end(), [](const Material& m) {
    return m.alpha_mode != Material::AlphaMode::opaque;
  });
  sync_lights();
  if (env_ready) choose_strategies();  // the local lights may have come or gone
}

Bounds3 Renderer::bounds() const {
  return impl_->bounds;
}
size_t Renderer::light_count() const {
  return impl_->lights.size() + impl_->punctual.size() + (impl_->sun_on ? 1 : 0);
}
const Environment& Renderer::environment() const {
  return impl_->env;
}
void RendererTesting::set_capture(Renderer& renderer, RayCapture* capture) {
  renderer.impl_->capture = capture;
}

void RendererTesting::set_wave_tiles(Renderer& renderer, size_t tiles) {
  renderer.impl_->tiles_per_wave = std::max<size_t>(1, tiles);
}

void RendererTesting::set_surface_rows(Renderer& renderer, bool on) {
  renderer.impl_->surface_rows_on = on;
}

std::array<double, 3> RendererTesting::retrace(const Renderer& renderer, const RayCapture& c) {
  const Renderer::Impl* impl_ = renderer.impl_.get();
  std::array<double, 3> ms{0, 0, 0};
  std::vector<SurfaceHit> hits;
  std::vector<uint8_t> blocked;
  auto run = [&](const std::vector<Ray>& rays, const std::vector<size_t>& batches, int kind) {
    size_t at = 0;
    const double t0 = now_ms();
    for (size_t b : batches) {
      std::span<const Ray> r(rays.data() + at, b);
      if (kind == 2) {
        blocked.resize(b);
        impl_->occluded(r, blocked);
      } else {
        hits.resize(b);
        impl_->trace(r, hits);
      }
      at += b;
    }
    ms[size_t(kind)] = now_ms() - t0;
  };
  run(c.camera, c.camera_batches, 0);
  run(c.bounce, c.bounce_batches, 1);
  run(c.shadow, c.shadow_batches, 2);
  return ms;
}

std::optional<DirectLighting> direct_lighting_from_name(const std::string& name) {
  if (name == "nee") return DirectLighting::nee;
  if (name == "restir") return DirectLighting::restir;
  if (name == "restir-unbiased") return DirectLighting::restir_unbiased;
  return std::nullopt;
}

void frame_jitter(uint32_t index, float& jx, float& jy) {
  jx = radical_inverse(2, index + 1), jy = radical_inverse(3, index + 1);
}

namespace {

void check_render_settings(const Camera& camera, const RenderSettings& s,
                           const std::optional<Camera>& prev_camera) {
  check_camera(camera);
  if (prev_camera) check_camera(*prev_camera);
  if (s.width <= 0 || s.height <= 0 || s.width > 32768 || s.height > 32768)
    throw Error(ErrorCode::invalid_argument,
                fmt::format("render: resolution {}x{} is out of range", s.width, s.height));
  if (s.spp <= 0)
    throw Error(ErrorCode::invalid_argument,
                fmt::format("render: spp must be positive, got {}", s.spp));
  if (s.max_depth <= 0)
    throw Error(ErrorCode::invalid_argument,
                fmt::format("render: max depth must be positive, got {}", s.max_depth));
  if (!(s.time_limit_s >= 0) || !(s.clamp >= 0))
    throw Error(ErrorCode::invalid_argument, "render: time limit and clamp must be >= 0");
  if (s.indirect_rate != 1.0f && s.indirect_rate != 0.5f && s.indirect_rate != 0.25f)
    throw Error(
        ErrorCode::invalid_argument,
        fmt::format("render: indirect rate must be 1, 0.5 or 0.25, got {}", s.indirect_rate));
  if (s.direct != DirectLighting::nee && s.direct != DirectLighting::restir &&
      s.direct != DirectLighting::restir_unbiased)
    throw Error(ErrorCode::invalid_argument, "render: unknown direct lighting method");
  if (s.restir_candidates < 1 || s.restir_candidates > 64 || s.restir_neighbors < 0 ||
      s.restir_neighbors > 16)
    throw Error(ErrorCode::invalid_argument,
                fmt::format("render: ReSTIR candidates must be in 1..64 and neighbours in 0..16, "
                            "got {} and {}",
                            s.restir_candidates, s.restir_neighbors));
}

// The frame's AOVs at pixel p: the means of the accumulated sums.
void finish_pixel(const Accumulator& acc, Frame& frame, size_t p) {
  const float inv = acc.n[p] > 0 ? 1.0f / float(acc.n[p]) : 0.0f;
  for (int c = 0; c < 3; ++c) {
    frame.aov[int(Aov::color)].pixels[3 * p + size_t(c)] = acc.color[3 * p + size_t(c)] * inv;
    frame.aov[int(Aov::albedo)].pixels[3 * p + size_t(c)] = acc.albedo[3 * p + size_t(c)] * inv;
    frame.aov[int(Aov::normal)].pixels[3 * p + size_t(c)] = acc.normal[3 * p + size_t(c)] * inv;
  }
  frame.aov[int(Aov::depth)].pixels[p] = acc.depth[p] * inv;
  frame.aov[int(Aov::roughness)].pixels[p] = acc.rough[p] * inv;
  frame.aov[int(Aov::motion)].pixels[2 * p] = acc.motion[2 * p] * inv;
  frame.aov[int(Aov::motion)].pixels[2 * p + 1] = acc.motion[2 * p + 1] * inv;
  frame.aov[int(Aov::spp)].pixels[p] = float(acc.n[p]);
  frame.aov[int(Aov::variance)].pixels[p] =
      acc.n[p] > 1 ? float(acc.lum_m2[p] / (acc.n[p] - 1) / acc.n[p]) : 0.0f;
}

}  // namespace

int render_tile_size() {
  return tile_size;
}

size_t render_tile_count(int width, int height) {
  return size_t((width + tile_size - 1) / tile_size) * size_t((height + tile_size - 1) / tile_size);
}

// One render over a list of tiles (every tile when `only` is null): passes outside, tiles
// inside, so each pixel sums its samples in pass order whichever tiles run together.
void Renderer::Impl::render_passes(const Camera& camera, const RenderSettings& s,
                                   const std::optional<Camera>& prev_camera,
                                   const std::vector<uint32_t>* only, Accumulator& acc,
                                   Frame& frame) {
  std::optional<ThreadLimit> limit;
  if (s.threads > 0 || capture) limit.emplace(capture ? 1 : s.threads);
  // The materials' textures, resolved for this render: the scene's textures are replaced
  // by set_materials at once, its materials (our copy) at the next commit.
  maps.assign(materials.size(), MaterialMaps{});
  for (size_t i = 0; i < materials.size(); ++i) {
    const Material& m = materials[i];
    const float r = (m.ior - 1.0f) / (m.ior + 1.0f);
    maps[i] = {texture(m.base_color_texture), texture(m.metallic_roughness_texture),
               texture(m.emission_texture), m.ior == 1.5f ? 0.04f : r * r};
  }
  const CameraModel cam(camera, s.width, s.height);
  const CameraModel prev(prev_camera ? *prev_camera : camera, s.width, s.height);
  const int tiles_x = (s.width + tile_size - 1) / tile_size;
  const size_t tiles = only ? only->size() : render_tile_count(s.width, s.height);
  const double start = now_ms();
  int passes = 0;
  size_t tiles_done = 0;
  WaveStats stats;
  std::vector<uint32_t> ids(std::min(tiles, tiles_per_wave));
  const bool use_tree = s.light_sampling == LightSampling::tree && !light_tree.empty();
  const bool restir = s.direct != DirectLighting::nee;
  if (!restir) restir_valid = false;
  if (!s.radiance_cache && cache_valid) radiance_cache.clear(), cache_valid = false;
  std::vector<std::vector<CacheRecord>> cache_records;
  for (int pass = 0; pass < s.spp; ++pass) {
    // ReSTIR's buffers: the history is the last pass (of this frame, or of frame - 1).
    RestirPass rp;
    if (restir) {
      RestirBuffer& last = this->restir[restir_last];
      const bool history = restir_valid && last.width == s.width && last.height == s.height &&
                           (pass > 0 || restir_frame + 1 == s.frame);
      RestirBuffer& cur = this->restir[1 - restir_last];
      const size_t pixels = size_t(s.width) * size_t(s.height);
      // Every pixel of a tile is written; a render of some tiles clears the others.
      if (only || cur.width != s.width || cur.height != s.height) {
        cur.width = s.width, cur.height = s.height;
        cur.res.assign(pixels, Reservoir{});
        cur.surf.assign(pixels, RestirSurface{});
      }
      rp = {history ? &last : nullptr, &cur, pass > 0};
    }
    float jx = 0.5f, jy = 0.5f;
    if (s.jitter)
      frame_jitter(s.fixed_jitter ? s.frame : s.frame * uint32_t(s.spp) + uint32_t(pass), jx, jy);
    if (pass == 0) frame.jitter_x = jx, frame.jitter_y = jy;
    // The radiance cache: kept from the last pass of this frame or of frame - 1.
    if (s.radiance_cache) {
      if (!(cache_valid && (pass > 0 || cache_frame + 1 == s.frame))) radiance_cache.clear();
      radiance_cache.set_view(cam.eye, 2 * cam.tan_half / float(s.height));
      for (auto& r : cache_records) r.clear();
      cache_records.resize(tiles);
    }
    // Waves of up to tiles_per_wave tiles in order (the same waves for any thread count).
    const render::SurfaceRowsKernels* rows =
        surface_rows_on ? &surface_rows_kernels(default_isa()) : nullptr;
    const WavePass wp{cam, prev, s, restir ? &rp : nullptr, pass, jx, jy, use_tree, rows};
    for (size_t w0 = 0; w0 < tiles; w0 += tiles_per_wave) {
      const size_t w1 = std::min(tiles, w0 + tiles_per_wave);
      for (size_t i = w0; i < w1; ++i) ids[i - w0] = only ? (*only)[i] : uint32_t(i);
      render_wave(wp, std::span<const uint32_t>(ids.data(), w1 - w0), tiles_x,
                  s.radiance_cache ? &cache_records[w0] : nullptr, acc, stats);
      tiles_done += w1 - w0;
      if (s.progress) {
        const double f = double(tiles_done) / double(tiles * size_t(s.spp));
        const int bar = int(f * 40);
        std::fprintf(stderr, "\rrender [%.*s%*s] %5.1f%%  %.1f s", bar,
                     "########################################", 40 - bar, "", 100 * f,
                     (now_ms() - start) / 1000);
      }
    }
    passes = pass + 1;
    if (s.radiance_cache) {  // the tiles' samples in tile order: the same for any threads
      for (const auto& r : cache_records) radiance_cache.add(r);
      radiance_cache.end_pass();
      cache_valid = true, cache_frame = s.frame;
    }
    if (restir) restir_last = 1 - restir_last, restir_valid = true, restir_frame = s.frame;
    if (s.time_limit_s > 0 && now_ms() - start >= s.time_limit_s * 1000) break;
  }
  if (s.progress) std::fprintf(stderr, "\n");
  frame.stats.ms += now_ms() - start;
  frame.stats.passes = passes;
  frame.stats.trace_ms += stats.trace_ms;
  frame.stats.total_thread_ms += stats.thread_ms;
  frame.stats.camera_rays += stats.rays[0];
  frame.stats.bounce_rays += stats.rays[1];
  frame.stats.shadow_rays += stats.rays[2];
  frame.stats.steps += stats.steps;
}

// One sample of a pixel into the sums: a NaN/Inf radiance is dropped (not smeared), then
// clamped when asked; the luminance's running mean and M2 (Welford) give the variance AOV.
void Accumulator::add(size_t p, Vec3 L, const PixelSample& o, float clamp) {
  if (!is_finite(L)) L = {0, 0, 0};
  L = clamped(L, clamp);
  if (float* const* aov = direct[0] ? direct.data() : nullptr) {
    // The mean of one sample, as the sums give it: 0 + x, times 1.
    for (int c = 0; c < 3; ++c) {
      aov[int(Aov::color)][3 * p + size_t(c)] = 0.0f + L[c];
      aov[int(Aov::albedo)][3 * p + size_t(c)] = 0.0f + o.albedo[c];
      aov[int(Aov::normal)][3 * p + size_t(c)] = 0.0f + o.normal[c];
    }
    aov[int(Aov::depth)][p] = 0.0f + o.depth;
    aov[int(Aov::roughness)][p] = 0.0f + o.roughness;
    aov[int(Aov::motion)][2 * p] = 0.0f + o.mx;
    aov[int(Aov::motion)][2 * p + 1] = 0.0f + o.my;
    aov[int(Aov::spp)][p] = 1.0f;
    aov[int(Aov::variance)][p] = 0.0f;
    return;
  }
  for (int c = 0; c < 3; ++c) {
    color[3 * p + size_t(c)] += L[c];
    albedo[3 * p + size_t(c)] += o.albedo[c];
    normal[3 * p + size_t(c)] += o.normal[c];
  }
  depth[p] += o.depth;
  rough[p] += o.roughness;
  motion[2 * p] += o.mx;
  motion[2 * p + 1] += o.my;
  const double lum = luminance(L);
  const int count = ++n[p];
  const double delta = lum - lum_mean[p];
  lum_mean[p] += delta / count;
  lum_m2[p] += delta * (lum - lum_mean[p]);
}

void Accumulator::reset(int w, int h) {
  width = w, height = h;
  const size_t p = size_t(w) * size_t(h);
  for (auto* v : {&color, &albedo, &normal}) v->resize(3 * p);
  for (auto* v : {&depth, &rough}) v->resize(p);
  motion.resize(2 * p), lum_mean.resize(p), lum_m2.resize(p), n.resize(p);
  parallel_for(0, p, 16384, [&](size_t b, size_t e) {
    for (auto* v : {&color, &albedo, &normal})
      std::fill(v->data() + 3 * b, v->data() + 3 * e, 0.0f);
    for (auto* v : {&depth, &rough}) std::fill(v->data() + b, v->data() + e, 0.0f);
    std::fill(motion.data() + 2 * b, motion.data() + 2 * e, 0.0f);
    std::fill(lum_mean.data() + b, lum_mean.data() + e, 0.0);
    std::fill(lum_m2.data() + b, lum_m2.data() + e, 0.0);
    std::fill(n.data() + b, n.data() + e, 0);
  });
}

Frame Renderer::render(const Camera& camera, const RenderSettings& s,
                       std::optional<Camera> prev_camera) {
  Frame frame;
  render(camera, s, prev_camera, frame);
  return frame;
}

void Renderer::render(const Camera& camera, const RenderSettings& s,
                      std::optional<Camera> prev_camera, Frame& frame) {
  check_render_settings(camera, s, prev_camera);
  if (impl_->scene->generation() != impl_->generation) impl_->sync();
  Accumulator& acc = impl_->acc;
  frame.stats = RenderStats{};
  // Every pixel of every AOV is written: the images' storage is reused.
  frame.width = s.width, frame.height = s.height;
  for (int a = 0; a < aov_count; ++a) frame.aov[a].reshape(s.width, s.height, aov_channels(Aov(a)));
  if (s.spp == 1) {  // one pass: the samples straight into the frame (the real-time loop)
    for (int a = 0; a < aov_count; ++a) acc.direct[size_t(a)] = frame.aov[a].pixels.data();
    struct Off {
      Accumulator& acc;
      ~Off() { acc.direct.fill(nullptr); }
    } off{acc};
    impl_->render_passes(camera, s, prev_camera, nullptr, acc, frame);
    return;
  }
  acc.reset(s.width, s.height);
  impl_->render_passes(camera, s, prev_camera, nullptr, acc, frame);
  // Means of the sums.
  parallel_for(0, size_t(s.height), 8, [&](size_t y0, size_t y1) {
    for (size_t p = y0 * size_t(s.width); p < y1 * size_t(s.width); ++p)
      finish_pixel(acc, frame, p);
  });
}

void Renderer::render_tiles(const Camera& camera, const RenderSettings& s,
                            std::span<const uint32_t> tiles, Frame& frame,
                            std::optional<Camera> prev_camera) {
  check_render_settings(camera, s, prev_camera);
  if (s.time_limit_s > 0)
    throw Error(ErrorCode::invalid_argument,
                "render: a time limit cannot be split into tiles (every tile needs every pass)");
  const size_t count = render_tile_count(s.width, s.height);
  for (uint32_t t : tiles)
    if (t >= count)
      throw Error(ErrorCode::invalid_argument, fmt::format("render: tile {} of {}", t, count));
  if (impl_->scene->generation() != impl_->generation) impl_->sync();
  if (frame.width != s.width || frame.height != s.height) {
    frame = Frame{};
    frame.width = s.width, frame.height = s.height;
    for (int a = 0; a < aov_count; ++a)
      frame.aov[a] = FloatImage(s.width, s.height, aov_channels(Aov(a)));
  }
  auto& acc = impl_->tile_acc;
  if (!acc || acc->width != s.width || acc->height != s.height)
    acc = std::make_unique<Accumulator>(s.width, s.height);
  const int tiles_x = (s.width + tile_size - 1) / tile_size;
  auto for_pixels = [&](uint32_t t, auto&& f) {
    const int x0 = int(t % uint32_t(tiles_x)) * tile_size,
              y0 = int(t / uint32_t(tiles_x)) * tile_size;
    for (int y = y0; y < std::min(y0 + tile_size, s.height); ++y)
      for (int x = x0; x < std::min(x0 + tile_size, s.width); ++x)
        f(size_t(y) * size_t(s.width) + size_t(x));
  };
  for (uint32_t t : tiles)  // this render's sums start from zero, as render()'s
    for_pixels(t, [&](size_t p) {
      for (int c = 0; c < 3; ++c)
        acc->color[3 * p + size_t(c)] = acc->albedo[3 * p + size_t(c)] =
            acc->normal[3 * p + size_t(c)] = 0;
      acc->depth[p] = acc->rough[p] = acc->motion[2 * p] = acc->motion[2 * p + 1] = 0;
      acc->lum_mean[p] = acc->lum_m2[p] = 0;
      acc->n[p] = 0;
    });
  const std::vector<uint32_t> list(tiles.begin(), tiles.end());
  impl_->render_passes(camera, s, prev_camera, &list, *acc, frame);
  for (uint32_t t : tiles) for_pixels(t, [&](size_t p) { finish_pixel(*acc, frame, p); });
}

}  // namespace kestrel
