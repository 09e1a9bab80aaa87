// The path tracer, wavefront per tile: a tile's paths advance one bounce at a time, so each
// bounce is one batch for trace() (camera rays as coherent packets) and one for occluded()
// (the next-event shadow rays). Per-sample random streams are seeded from (seed, frame,
// pixel, sample), tiles write disjoint pixels, so the image does not depend on threads.
#include <fmt/format.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <unordered_map>

#include "core/parallel.h"
#include "core/timer.h"
#include "core/vec.h"
#include "kestrel/error.h"
#include "kestrel/parallel.h"
#include "kestrel/render.h"
#include "render/bsdf.h"
#include "render/sampling.h"

namespace kestrel {

using namespace render;

namespace {

constexpr int tile_size = 32;
constexpr float specular_alpha = 0.01f;  // surfaces below this alpha (and metallic) are "specular" for the AOVs

float srgb_to_linear(float c) { return c <= 0.04045f ? c / 12.92f : std::pow((c + 0.055f) / 1.055f, 2.4f); }

struct SrgbTable {
  float v[256];
  SrgbTable() {
    for (int i = 0; i < 256; ++i) v[i] = srgb_to_linear(float(i) / 255.0f);
  }
};
const SrgbTable srgb_table;

// Bilinear, repeat-wrapped texture fetch; sRGB-decoded per texel when `srgb`.
void sample_texture(const Texture& tex, Vec2 uv, bool srgb, float out[4]) {
  float x = (uv.x - std::floor(uv.x)) * float(tex.width) - 0.5f;
  float y = (uv.y - std::floor(uv.y)) * float(tex.height) - 0.5f;
  if (!(x >= -1.0f && x < float(tex.width)) || !(y >= -1.0f && y < float(tex.height))) x = 0, y = 0;  // NaN uv
  const float fx = std::floor(x), fy = std::floor(y);
  const float wx = x - fx, wy = y - fy;
  // x in [-0.5, w - 0.5): the left texel is -1 (wraps to w - 1) .. w - 1, the right one 0 .. w.
  int x0 = int(fx), y0 = int(fy);
  int x1 = x0 + 1, y1 = y0 + 1;
  if (x0 < 0) x0 = tex.width - 1;
  if (x1 >= tex.width) x1 = 0;
  if (y0 < 0) y0 = tex.height - 1;
  if (y1 >= tex.height) y1 = 0;
  const uint8_t* row0 = &tex.rgba[size_t(y0) * size_t(tex.width) * 4];
  const uint8_t* row1 = &tex.rgba[size_t(y1) * size_t(tex.width) * 4];
  const uint8_t* t00 = row0 + size_t(x0) * 4;
  const uint8_t* t10 = row0 + size_t(x1) * 4;
  const uint8_t* t01 = row1 + size_t(x0) * 4;
  const uint8_t* t11 = row1 + size_t(x1) * 4;
  const float w00 = (1 - wx) * (1 - wy), w10 = wx * (1 - wy), w01 = (1 - wx) * wy, w11 = wx * wy;
  if (srgb) {
    const float* lut = srgb_table.v;
    for (int c = 0; c < 3; ++c) out[c] = lut[t00[c]] * w00 + lut[t10[c]] * w10 + lut[t01[c]] * w01 + lut[t11[c]] * w11;
  } else {
    for (int c = 0; c < 3; ++c) out[c] = (float(t00[c]) * w00 + float(t10[c]) * w10 + float(t01[c]) * w01 + float(t11[c]) * w11) * (1.0f / 255.0f);
  }
  out[3] = (float(t00[3]) * w00 + float(t10[3]) * w10 + float(t01[3]) * w01 + float(t11[3]) * w11) * (1.0f / 255.0f);
}

// Texture coordinates at barycentrics (1 - b1 - b2, b1, b2) of a triangle; (0, 0) without uvs.
Vec2 uv_at(const TriangleMesh& m, uint32_t prim, float b1, float b2) {
  if (m.uvs.empty()) return {0, 0};
  const size_t tri = 3 * size_t(prim);
  const Vec2 a = m.uvs[m.indices[tri]], b = m.uvs[m.indices[tri + 1]], c = m.uvs[m.indices[tri + 2]];
  const float b0 = 1 - b1 - b2;
  return {a.x * b0 + b.x * b1 + c.x * b2, a.y * b0 + b.y * b1 + c.y * b2};
}

Vec3 normal_transform(const float n[9], Vec3 v) {
  return {n[0] * v.x + n[1] * v.y + n[2] * v.z, n[3] * v.x + n[4] * v.y + n[5] * v.z, n[6] * v.x + n[7] * v.y + n[8] * v.z};
}

// Camera basis and projection, shared by ray generation and motion vectors.
struct CameraModel {
  Vec3 eye, forward, right, up;
  float tan_half, aspect, focus, aperture;
  int width, height;
  CameraModel(const Camera& c, int w, int h) : width(w), height(h) {
    eye = c.eye;
    forward = normalize(c.target - c.eye);
    right = cross(forward, Vec3{0, 1, 0});
    if (length(right) < 1e-6f) right = Vec3{1, 0, 0};
    right = normalize(right);
    up = cross(right, forward);
    tan_half = std::tan(c.vfov_degrees * 0.5f * pi / 180.0f);
    aspect = float(w) / float(h);
    focus = c.focus_distance > 0 ? c.focus_distance : length(c.target - c.eye);
    aperture = c.aperture_radius;
  }
  // Film position (fx, fy) in pixels (pixel centres at +0.5); lens sample in [0,1)^2.
  Ray ray(float fx, float fy, float lu, float lv) const {
    const float sx = (2.0f * fx / float(width) - 1.0f) * tan_half * aspect;
    const float sy = (1.0f - 2.0f * fy / float(height)) * tan_half;
    const Vec3 d = forward + right * sx + up * sy;
    if (aperture <= 0) return Ray{eye, normalize(d), 0.0f, INFINITY};
    // Concentric disk (Shirley-Chiu) on the lens, aimed at the focus plane.
    const float a = 2 * lu - 1, b = 2 * lv - 1;
    float r = 0, phi = 0;
    if (a != 0 || b != 0) {
      if (std::fabs(a) > std::fabs(b)) r = a, phi = (pi / 4) * (b / a);
      else r = b, phi = pi / 2 - (pi / 4) * (a / b);
    }
    const Vec3 o = eye + right * (aperture * r * std::cos(phi)) + up * (aperture * r * std::sin(phi));
    const Vec3 focus_point = eye + d * focus;
    return Ray{o, normalize(focus_point - o), 0.0f, INFINITY};
  }
  // Film position of a world point; false when it is not in front of the camera.
  bool project(Vec3 p, float& fx, float& fy) const {
    const Vec3 d = p - eye;
    const float z = dot(d, forward);
    if (!(z > 1e-6f)) return false;
    const float sx = dot(d, right) / (z * tan_half * aspect);
    const float sy = dot(d, up) / (z * tan_half);
    fx = (sx + 1.0f) * 0.5f * float(width);
    fy = (1.0f - sy) * 0.5f * float(height);
    return true;
  }
};

double now_ms() { return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now().time_since_epoch()).count(); }

}  // namespace

// ---- scene access -----------------------------------------------------------------------------

struct Accumulator;

/// A hit as the shading code sees it: the instance (static scenes: the mesh) and the
/// triangle's index in that instance's mesh.
struct SurfaceHit {
  float t = INFINITY;
  uint32_t instance = invalid_id, prim = invalid_id;
  float u = 0, v = 0;
  bool hit() const { return instance != invalid_id; }
};

struct Renderer::Impl {
  struct InstanceShade {
    const TriangleMesh* mesh = nullptr;
    uint32_t mesh_key = 0;  // index into emissive_rank
    bool identity = true;
    Affine3 xf, prev_xf;
    float nrm[9] = {1, 0, 0, 0, 1, 0, 0, 0, 1};  // inverse transpose of xf's linear part
    uint32_t light_base = 0;
  };
  struct LightTri {
    uint32_t instance, prim;
    Vec3 p0, e1, e2;
    float area;
  };

  const InstancedScene* scene = nullptr;  // referenced: it outlives the renderer
  uint64_t generation = 0;                 // the scene's commit the shading data are of
  std::vector<Material> materials;         // the scene's, plus a trailing "default"
  std::vector<InstanceShade> instances;
  std::vector<std::vector<int32_t>> emissive_rank;  // per mesh key, per triangle: rank or -1
  std::vector<LightTri> lights;
  Distribution1D light_dist;
  Environment env;
  bool env_on = false;
  Distribution1D env_rows;
  std::vector<Distribution1D> env_cols;
  float p_env = 0;  // probability NEE samples the environment
  Bounds3 bounds;
  RayCapture* capture = nullptr;
  std::unique_ptr<Accumulator> tile_acc;  // render_tiles: sums kept between calls of one size
  void render_passes(const Camera& camera, const RenderSettings& s, const std::optional<Camera>& prev_camera,
                     const std::vector<uint32_t>* only, Accumulator& acc, Frame& frame);

  const Material& material_of(const TriangleMesh& m, uint32_t prim) const {
    const uint32_t id = prim < m.material_ids.size() ? m.material_ids[prim] : uint32_t(materials.size() - 1);
    return materials[std::min<size_t>(id, materials.size() - 1)];
  }
  const Texture* texture(int index) const {
    const std::vector<Texture>& textures = scene->textures();
    if (index < 0 || size_t(index) >= textures.size()) return nullptr;
    const Texture& t = textures[size_t(index)];
    return t.width > 0 && t.height > 0 && t.rgba.size() == size_t(t.width) * size_t(t.height) * 4 ? &t : nullptr;
  }
  Vec3 emission_at(const Material& m, Vec2 uv) const {
    Vec3 e = m.emission;
    if (const Texture* t = texture(m.emission_texture)) {
      float px[4];
      sample_texture(*t, uv, true, px);
      e = e * Vec3{px[0], px[1], px[2]};
    }
    return e;
  }

  // A trailing "default" material (what out-of-range ids fall back to), every one checked.
  void check_materials(const std::string& source) {
    if (materials.empty() || materials.back().name != "default") materials.push_back(Material{.name = "default"});
    for (size_t i = 0; i < materials.size(); ++i) {
      const Material& m = materials[i];
      if (!is_finite(m.base_color) || !is_finite(m.emission) || !std::isfinite(m.metallic) || !std::isfinite(m.roughness) ||
          !std::isfinite(m.specular) || m.emission.x < 0 || m.emission.y < 0 || m.emission.z < 0)
        throw Error(ErrorCode::invalid_argument,
                    fmt::format("{}: material {} '{}': a non-finite or negative parameter", source, i, m.name));
    }
  }

  // After the lights are known: the given environment, else the sky when nothing emits.
  void choose_environment(std::optional<Environment> environment) {
    if (environment) env = std::move(*environment);
    else env = Environment::parse(lights.empty() ? "sky" : "none");
    setup_environment();
  }

  void setup_environment() {
    env_on = env.scale > 0 && (!env.image.pixels.empty() || luminance(env.color) > 0);
    if (!env.image.pixels.empty()) {
      const int w = env.image.width, h = env.image.height;
      std::vector<float> row_weights(static_cast<size_t>(h), 0.0f);
      env_cols.clear();
      for (int y = 0; y < h; ++y) {
        const float sin_theta = std::sin(pi * (float(y) + 0.5f) / float(h));
        std::vector<float> cols(static_cast<size_t>(w), 0.0f);
        for (int x = 0; x < w; ++x) {
          const float* p = env.image.at(x, y);
          cols[size_t(x)] = luminance({p[0], p[1], p[2]}) * sin_theta + 1e-8f;
        }
        env_cols.emplace_back(cols);
        row_weights[size_t(y)] = env_cols.back().total();
      }
      env_rows = Distribution1D(row_weights);
    }
    p_env = !env_on ? 0.0f : (lights.empty() ? 1.0f : 0.5f);
  }

  Vec3 env_radiance(Vec3 d) const {
    if (!env_on) return {0, 0, 0};
    if (env.image.pixels.empty()) {
      if (!env.overcast) return env.color * env.scale;
      const float cos_theta = d.y / std::sqrt(dot(d, d));
      return env.color * (env.scale * (cos_theta > 0 ? (1.0f + 2.0f * cos_theta) * (1.0f / 3.0f) : 0.1f));
    }
    const float u = 0.5f + std::atan2(d.x, -d.z) / (2 * pi);
    const float v = std::acos(std::clamp(d.y, -1.0f, 1.0f)) / pi;
    const int x = std::clamp(int(u * float(env.image.width)), 0, env.image.width - 1);
    const int y = std::clamp(int(v * float(env.image.height)), 0, env.image.height - 1);
    const float* p = env.image.at(x, y);
    return Vec3{p[0], p[1], p[2]} * env.scale;
  }
  // Solid-angle pdf of sampling direction d from the environment (given it was chosen), at a
  // point with shading normal n: a constant environment is sampled cosine-weighted about n
  // (every sample above the surface), an image by its luminance.
  float env_pdf(Vec3 d, Vec3 n) const {
    if (env.image.pixels.empty()) return std::max(0.0f, dot(d, n)) / pi;
    const float u = 0.5f + std::atan2(d.x, -d.z) / (2 * pi);
    const float theta = std::acos(std::clamp(d.y, -1.0f, 1.0f));
    const int w = env.image.width, h = env.image.height;
    const int x = std::clamp(int(u * float(w)), 0, w - 1);
    const int y = std::clamp(int(theta / pi * float(h)), 0, h - 1);
    const float sin_theta = std::sin(theta);
    if (sin_theta <= 0) return 0;
    const float pdf_uv = env_rows.pmf(size_t(y)) * env_cols[size_t(y)].pmf(size_t(x)) * float(w) * float(h);
    return pdf_uv / (2 * pi * pi * sin_theta);
  }
  Vec3 env_sample(float u1, float u2, Vec3 n, float& pdf) const {
    if (env.image.pixels.empty()) {
      const float r = std::sqrt(u1), phi = 2 * pi * u2;
      const Vec3 local{r * std::cos(phi), r * std::sin(phi), std::sqrt(std::max(0.0f, 1.0f - u1))};
      const Vec3 d = Basis(n).to_world(local);
      pdf = env_pdf(d, n);
      return d;
    }
    float ru, cu;
    const size_t y = env_rows.sample(u1, &ru);
    const size_t x = env_cols[y].sample(u2, &cu);
    const float u = (float(x) + cu) / float(env.image.width);
    const float v = (float(y) + ru) / float(env.image.height);
    const float theta = v * pi, phi = (u - 0.5f) * 2 * pi;
    const Vec3 d{std::sin(theta) * std::sin(phi), std::cos(theta), -std::sin(theta) * std::cos(phi)};
    pdf = env_pdf(d, n);
    return d;
  }

  // World-space triangle of (instance, prim).
  void world_triangle(const InstanceShade& is, uint32_t prim, Vec3& p0, Vec3& p1, Vec3& p2) const {
    const TriangleMesh& m = *is.mesh;
    p0 = m.positions[m.indices[3 * prim]];
    p1 = m.positions[m.indices[3 * prim + 1]];
    p2 = m.positions[m.indices[3 * prim + 2]];
    if (!is.identity) p0 = is.xf.point(p0), p1 = is.xf.point(p1), p2 = is.xf.point(p2);
  }

  bool valid_triangle(const TriangleMesh& m, uint32_t prim) const {
    for (int k = 0; k < 3; ++k) {
      const uint32_t i = m.indices[3 * prim + k];
      if (i >= m.positions.size() || !is_finite(m.positions[i])) return false;
    }
    return true;
  }

  void sync_lights() {
    // Emissive triangles by mesh, then world-space light triangles for every instance.
    std::unordered_map<const TriangleMesh*, uint32_t> key_of;
    emissive_rank.clear();
    lights.clear();
    std::vector<float> power;
    bounds = Bounds3{};
    for (uint32_t i = 0; i < instances.size(); ++i) {
      InstanceShade& is = instances[i];
      if (!is.mesh) continue;
      auto [it, fresh] = key_of.try_emplace(is.mesh, uint32_t(emissive_rank.size()));
      if (fresh) {
        std::vector<int32_t> rank(is.mesh->triangle_count(), -1);
        int32_t n = 0;
        for (uint32_t p = 0; p < rank.size(); ++p) {
          const Material& m = material_of(*is.mesh, p);
          if ((luminance(m.emission) > 0) && valid_triangle(*is.mesh, p)) rank[p] = n++;
        }
        emissive_rank.push_back(std::move(rank));
      }
      is.mesh_key = it->second;
      is.light_base = uint32_t(lights.size());
      const std::vector<int32_t>& rank = emissive_rank[is.mesh_key];
      for (uint32_t p = 0; p < rank.size(); ++p) {
        if (rank[p] < 0) continue;
        Vec3 p0, p1, p2;
        world_triangle(is, p, p0, p1, p2);
        const float area = 0.5f * length(cross(p1 - p0, p2 - p0));
        lights.push_back({i, p, p0, p1 - p0, p2 - p0, area});
        power.push_back(area > 0 ? luminance(material_of(*is.mesh, p).emission) * area * 2 * pi : 0.0f);
      }
      const TriangleMesh& m = *is.mesh;
      for (uint32_t t = 0; t < m.triangle_count(); ++t) {
        if (!valid_triangle(m, t)) continue;
        Vec3 p0, p1, p2;
        world_triangle(is, t, p0, p1, p2);
        extend(bounds, p0), extend(bounds, p1), extend(bounds, p2);
      }
    }
    light_dist = Distribution1D(power);
    if (light_dist.total() <= 0) lights.clear();
  }

  // Probability (solid angle) that NEE picked this point on light triangle (instance, prim).
  float light_pdf(uint32_t instance, uint32_t prim, float dist2, float cos_light) const {
    if (lights.empty() || cos_light <= 0) return 0;
    const InstanceShade& is = instances[instance];
    const int32_t r = emissive_rank[is.mesh_key][prim];
    if (r < 0) return 0;
    return light_pdf_of(is.light_base + size_t(r), dist2, cos_light);
  }
  // The same for light li (solid angle: pick probability / area * distance^2 / cos).
  float light_pdf_of(size_t li, float dist2, float cos_light) const {
    const LightTri& l = lights[li];
    if (cos_light <= 0 || l.area <= 0) return 0;
    return (1 - p_env) * light_dist.pmf(li) / l.area * dist2 / cos_light;
  }

  std::string source() const;
  void sync();
  void trace(std::span<const Ray> rays, std::span<SurfaceHit> hits) const;
  void occluded(std::span<const Ray> rays, std::span<uint8_t> out) const;
  void render_tile(const CameraModel& cam, const CameraModel& prev_cam, const RenderSettings& s, int tx, int ty, int pass,
                   float jx, float jy, Accumulator& acc, double& trace_ms, uint64_t ray_counts[3]) const;
};

void Renderer::Impl::trace(std::span<const Ray> rays, std::span<SurfaceHit> hits) const {
  thread_local std::vector<InstanceHit> h;  // scratch, reused by every batch of this thread
  h.resize(rays.size());
  scene->trace(rays, std::span<InstanceHit>(h.data(), rays.size()));
  for (size_t i = 0; i < rays.size(); ++i) hits[i] = {h[i].t, h[i].instance_id, h[i].prim_id, h[i].u, h[i].v};
}

void Renderer::Impl::occluded(std::span<const Ray> rays, std::span<uint8_t> out) const { scene->occluded(rays, out); }

// ---- per-pixel accumulation ----------------------------------------------------------------

struct Accumulator {
  int width, height;
  std::vector<float> color, albedo, normal, depth, rough, motion;  // sums
  std::vector<double> lum_mean, lum_m2;                             // Welford on luminance
  std::vector<int> n;
  Accumulator(int w, int h) : width(w), height(h) {
    const size_t p = size_t(w) * size_t(h);
    color.assign(3 * p, 0), albedo.assign(3 * p, 0), normal.assign(3 * p, 0), depth.assign(p, 0), rough.assign(p, 0);
    motion.assign(2 * p, 0), lum_mean.assign(p, 0), lum_m2.assign(p, 0), n.assign(p, 0);
  }
};

namespace {

struct PathState {
  Vec3 throughput{1, 1, 1}, radiance{0, 0, 0};
  uint32_t pixel;      // index into the tile's pixel list
  float bsdf_pdf = 0;  // pdf of the direction that led here (solid angle)
  Vec3 prev_normal{0, 0, 1};  // shading normal where that direction was sampled
  bool aov_pending = true;
};

struct PixelSample {
  Vec3 albedo{0, 0, 0}, normal{0, 0, 0};
  float depth = 0, roughness = 0, mx = 0, my = 0;
};

struct Shadow {
  Vec3 contribution;
  uint32_t path;
};

Vec3 offset_origin(Vec3 p, Vec3 n) {
  const float scale = 1.0f + std::max({std::fabs(p.x), std::fabs(p.y), std::fabs(p.z)});
  return p + n * (2e-5f * scale);
}

}  // namespace

void Renderer::Impl::render_tile(const CameraModel& cam, const CameraModel& prev_cam, const RenderSettings& s, int tx,
                                 int ty, int pass, float jx, float jy, Accumulator& acc, double& trace_ms,
                                 uint64_t ray_counts[3]) const {
  const int x0 = tx * tile_size, y0 = ty * tile_size;
  const int x1 = std::min(x0 + tile_size, s.width), y1 = std::min(y0 + tile_size, s.height);
  const size_t count = size_t(x1 - x0) * size_t(y1 - y0);
  std::vector<Rng> rngs;
  std::vector<PathState> paths(count);
  std::vector<PixelSample> px(count);
  std::vector<Ray> rays(count), next_rays;
  std::vector<SurfaceHit> hits(count);
  std::vector<uint32_t> active(count), next_active;
  std::vector<Ray> shadow_rays;
  std::vector<Shadow> shadows;
  std::vector<uint8_t> blocked;
  rngs.reserve(count);
  for (size_t i = 0; i < count; ++i) {
    const int x = x0 + int(i % size_t(x1 - x0)), y = y0 + int(i / size_t(x1 - x0));
    const uint64_t pixel = uint64_t(y) * uint64_t(s.width) + uint64_t(x);
    rngs.emplace_back(s.seed, s.frame, pixel, uint64_t(pass));
    Rng& rng = rngs.back();
    const float lu = rng.uniform(), lv = rng.uniform();
    rays[i] = cam.ray(float(x) + jx, float(y) + jy, lu, lv);
    paths[i].pixel = uint32_t(i);
    active[i] = uint32_t(i);
  }
  auto timed = [&](auto&& fn, int kind, size_t n) {
    const double t0 = now_ms();
    fn();
    trace_ms += now_ms() - t0;
    ray_counts[kind] += n;
  };
  auto capture_batch = [&](int kind, std::span<const Ray> r) {
    if (!capture) return;
    std::vector<Ray>& dst = kind == 0 ? capture->camera : kind == 1 ? capture->bounce : capture->shadow;
    dst.insert(dst.end(), r.begin(), r.end());
    (kind == 0 ? capture->camera_batches : kind == 1 ? capture->bounce_batches : capture->shadow_batches).push_back(r.size());
  };

  for (int depth = 0; !active.empty(); ++depth) {
    const size_t n = active.size();
    hits.resize(n);
    capture_batch(depth == 0 ? 0 : 1, std::span<const Ray>(rays.data(), n));
    timed([&] { trace(std::span<const Ray>(rays.data(), n), hits); }, depth == 0 ? 0 : 1, n);
    next_rays.clear();
    next_active.clear();
    shadow_rays.clear();
    shadows.clear();
    // Shading reads scattered vertex data: fetch it ahead, indices first, then the vertices
    // they name (misses overlap instead of stalling one hit at a time).
    auto prefetch_indices = [&](size_t k) {
      const SurfaceHit& h = hits[k];
      if (!h.hit()) return;
      const TriangleMesh& m = *instances[h.instance].mesh;
      __builtin_prefetch(&m.indices[3 * size_t(h.prim)]);
      if (!m.material_ids.empty()) __builtin_prefetch(&m.material_ids[h.prim]);
    };
    auto prefetch_vertices = [&](size_t k) {
      const SurfaceHit& h = hits[k];
      if (!h.hit()) return;
      const TriangleMesh& m = *instances[h.instance].mesh;
      for (int c = 0; c < 3; ++c) {
        const uint32_t i = m.indices[3 * size_t(h.prim) + size_t(c)];
        __builtin_prefetch(&m.positions[i]);
        if (!m.normals.empty()) __builtin_prefetch(&m.normals[i]);
        if (!m.uvs.empty()) __builtin_prefetch(&m.uvs[i]);
      }
    };
    auto prefetch_texels = [&](size_t k) {  // the base colour texels, once the uvs are near
      const SurfaceHit& h = hits[k];
      if (!h.hit()) return;
      const TriangleMesh& m = *instances[h.instance].mesh;
      if (m.uvs.empty()) return;
      const Texture* t = texture(material_of(m, h.prim).base_color_texture);
      if (!t) return;
      const Vec2 uv = uv_at(m, h.prim, h.u, h.v);
      const float u = uv.x, v = uv.y;
      const float x = (u - std::floor(u)) * float(t->width), y = (v - std::floor(v)) * float(t->height);
      if (!(x >= 0 && x < float(t->width) && y >= 0 && y < float(t->height))) return;
      const size_t row = size_t(y) * size_t(t->width);
      __builtin_prefetch(&t->rgba[(row + size_t(x)) * 4]);
      if (size_t(y) + 1 < size_t(t->height)) __builtin_prefetch(&t->rgba[(row + size_t(t->width) + size_t(x)) * 4]);
    };
    constexpr size_t index_distance = 48, vertex_distance = 24, texel_distance = 12;
    for (size_t k = 0; k < std::min(n, index_distance); ++k) prefetch_indices(k);
    for (size_t k = 0; k < std::min(n, vertex_distance); ++k) prefetch_vertices(k);
    for (size_t k = 0; k < std::min(n, texel_distance); ++k) prefetch_texels(k);
    for (size_t k = 0; k < n; ++k) {
      if (k + index_distance < n) prefetch_indices(k + index_distance);
      if (k + vertex_distance < n) prefetch_vertices(k + vertex_distance);
      if (k + texel_distance < n) prefetch_texels(k + texel_distance);
      PathState& ps = paths[active[k]];
      Rng& rng = rngs[active[k]];
      PixelSample& out = px[ps.pixel];
      const Ray& ray = rays[k];
      const SurfaceHit& h = hits[k];
      if (!h.hit()) {
        const Vec3 le = env_radiance(ray.dir);
        float w = 1;
        if (depth > 0 && p_env > 0) {
          const float lp = p_env * env_pdf(ray.dir, ps.prev_normal);
          w = ps.bsdf_pdf * ps.bsdf_pdf / (ps.bsdf_pdf * ps.bsdf_pdf + lp * lp);
        }
        ps.radiance = ps.radiance + ps.throughput * le * w;
        if (ps.aov_pending) {
          out.albedo = min(le, Vec3{1, 1, 1});
          out.normal = {0, 0, 0};
          out.roughness = 0;
        }
        continue;
      }
      // Surface interaction.
      const InstanceShade& is = instances[h.instance];
      const TriangleMesh& mesh = *is.mesh;
      const uint32_t i0 = mesh.indices[3 * h.prim], i1 = mesh.indices[3 * h.prim + 1], i2 = mesh.indices[3 * h.prim + 2];
      const float b0 = 1 - h.u - h.v;
      Vec3 p0 = mesh.positions[i0], p1 = mesh.positions[i1], p2 = mesh.positions[i2];
      const Vec3 p_obj = p0 * b0 + p1 * h.u + p2 * h.v;
      if (!is.identity) p0 = is.xf.point(p0), p1 = is.xf.point(p1), p2 = is.xf.point(p2);
      const Vec3 p = p0 * b0 + p1 * h.u + p2 * h.v;
      const Vec3 wo = -ray.dir;
      Vec3 ng = cross(p1 - p0, p2 - p0);
      const float ng_len = length(ng);
      ng = ng_len > 0 ? ng * (1.0f / ng_len) : -wo;
      const float cos_hit = dot(ng, wo);
      if (cos_hit < 0) ng = -ng;
      Vec3 ns = ng;
      if (!mesh.normals.empty()) {
        Vec3 nn = mesh.normals[i0] * b0 + mesh.normals[i1] * h.u + mesh.normals[i2] * h.v;
        if (!is.identity) nn = normal_transform(is.nrm, nn);
        const float len = length(nn);
        if (len > 0 && std::isfinite(len)) {
          nn = nn * (1.0f / len);
          if (dot(nn, ng) < 0) nn = -nn;
          if (dot(nn, wo) > 1e-4f) ns = nn;
        }
      }
      const Vec2 uv = uv_at(mesh, h.prim, h.u, h.v);
      const Material& mat = material_of(mesh, h.prim);
      BsdfParams bp;
      bp.base = mat.base_color;
      float roughness = mat.roughness;
      bp.metallic = mat.metallic;
      if (const Texture* t = texture(mat.base_color_texture)) {
        float c[4];
        sample_texture(*t, uv, true, c);
        bp.base = bp.base * Vec3{c[0], c[1], c[2]};
      }
      if (const Texture* t = texture(mat.metallic_roughness_texture)) {
        float c[4];
        sample_texture(*t, uv, false, c);
        roughness *= c[1];
        bp.metallic *= c[2];
      }
      bp.base = min(max(bp.base, Vec3{0, 0, 0}), Vec3{1, 1, 1});
      bp.metallic = std::clamp(bp.metallic, 0.0f, 1.0f);
      roughness = std::clamp(roughness, 0.0f, 1.0f);
      bp.alpha = std::max(roughness * roughness, min_alpha);
      bp.specular = std::clamp(mat.specular, 0.0f, 1.0f);

      if (depth == 0) {
        out.depth = dot(p - cam.eye, cam.forward);
        const Vec3 p_prev = is.identity ? p : is.prev_xf.point(p_obj);
        float fx, fy, gx, gy;
        if (cam.project(p, fx, fy) && prev_cam.project(p_prev, gx, gy)) out.mx = gx - fx, out.my = gy - fy;
      }
      const bool specular_surface = bp.metallic >= 0.5f && bp.alpha < specular_alpha;
      if (ps.aov_pending) {
        out.albedo = bp.base;
        out.normal = ns;
        out.roughness = roughness;
        if (!specular_surface || depth >= 3) ps.aov_pending = false;
      }
      // Emission (two-sided), weighted against light sampling.
      if (luminance(mat.emission) > 0) {
        const Vec3 le = emission_at(mat, uv);
        float w = 1;
        if (depth > 0) {
          const float lp = light_pdf(h.instance, h.prim, h.t * h.t, std::fabs(cos_hit));
          w = ps.bsdf_pdf * ps.bsdf_pdf / (ps.bsdf_pdf * ps.bsdf_pdf + lp * lp);
        }
        ps.radiance = ps.radiance + ps.throughput * le * w;
      }
      if (depth + 1 >= s.max_depth) continue;
      const Basis frame(ns);
      const Vec3 wo_l = frame.to_local(wo);
      const Vec3 origin = offset_origin(p, ng);
      // Next-event estimation: one light sample (an emissive triangle or the environment).
      if (p_env > 0 || !lights.empty()) {
        const float ul = rng.uniform(), u1 = rng.uniform(), u2 = rng.uniform();
        Vec3 wi, le;
        float pdf = 0, tmax = INFINITY;
        Vec3 dir;
        if (ul < p_env) {
          float epdf;
          wi = env_sample(u1, u2, ns, epdf);
          pdf = p_env * epdf;
          le = env_radiance(wi);
          dir = wi;
        } else {
          const size_t li = light_dist.sample(lights.size() == 1 ? 0.5f : (ul - p_env) / (1 - p_env));
          const LightTri& l = lights[li];
          const float su = std::sqrt(u1);
          const float lb1 = u2 * su, lb2 = 1 - su;  // weights of vertices 1 and 2
          const Vec3 q = l.p0 + l.e1 * lb1 + l.e2 * lb2;
          dir = q - origin;
          const float dist2 = dot(dir, dir);
          wi = dir * (1.0f / std::sqrt(dist2));
          Vec3 nl = cross(l.e1, l.e2);
          const float cos_l = std::fabs(dot(normalize(nl), wi));
          const InstanceShade& lis = instances[l.instance];
          const Material& lm = material_of(*lis.mesh, l.prim);
          le = emission_at(lm, uv_at(*lis.mesh, l.prim, lb1, lb2));
          pdf = light_pdf_of(li, dist2, cos_l);
          tmax = 1.0f - 1e-3f;
        }
        if (pdf > 0 && dot(wi, ng) > 0 && luminance(le) > 0) {
          const Vec3 wi_l = frame.to_local(wi);
          const Vec3 f = bsdf_eval(bp, wo_l, wi_l);
          if (luminance(f) > 0) {
            const float bpdf = bsdf_pdf(bp, wo_l, wi_l);
            const float w = pdf * pdf / (pdf * pdf + bpdf * bpdf);
            shadow_rays.push_back(Ray{origin, dir, 0.0f, tmax});
            shadows.push_back({ps.throughput * f * le * (w / pdf), active[k]});
          }
        }
      }
      // Continue the path by sampling the BSDF.
      const float u0 = rng.uniform(), u1 = rng.uniform(), u2 = rng.uniform();
      BsdfSample bs;
      if (!bsdf_sample(bp, wo_l, u0, u1, u2, bs)) continue;
      const Vec3 wi = frame.to_world(bs.wi);
      if (dot(wi, ng) <= 0) continue;
      ps.throughput = ps.throughput * bs.weight;
      ps.bsdf_pdf = bs.pdf;
      ps.prev_normal = ns;
      if (depth + 1 >= s.rr_depth) {
        const float q = std::min(0.95f, std::max({ps.throughput.x, ps.throughput.y, ps.throughput.z}));
        if (!(rng.uniform() < q)) continue;
        ps.throughput = ps.throughput * (1.0f / q);
      }
      next_rays.push_back(Ray{origin, wi, 0.0f, INFINITY});
      next_active.push_back(active[k]);
    }
    if (!shadow_rays.empty()) {
      blocked.resize(shadow_rays.size());
      capture_batch(2, shadow_rays);
      timed([&] { occluded(shadow_rays, blocked); }, 2, shadow_rays.size());
      for (size_t i = 0; i < shadows.size(); ++i)
        if (!blocked[i]) paths[shadows[i].path].radiance = paths[shadows[i].path].radiance + shadows[i].contribution;
    }
    rays.swap(next_rays);
    active.swap(next_active);
  }

  for (size_t i = 0; i < count; ++i) {
    const int x = x0 + int(i % size_t(x1 - x0)), y = y0 + int(i / size_t(x1 - x0));
    const size_t p = size_t(y) * size_t(s.width) + size_t(x);
    Vec3 L = paths[i].radiance;
    if (!is_finite(L)) L = {0, 0, 0};  // a NaN/Inf sample is dropped, not smeared
    if (s.clamp > 0) {
      const float m = std::max({L.x, L.y, L.z});
      if (m > s.clamp) L = L * (s.clamp / m);
    }
    const PixelSample& o = px[i];
    for (int c = 0; c < 3; ++c) {
      acc.color[3 * p + size_t(c)] += L[c];
      acc.albedo[3 * p + size_t(c)] += o.albedo[c];
      acc.normal[3 * p + size_t(c)] += o.normal[c];
    }
    acc.depth[p] += o.depth;
    acc.rough[p] += o.roughness;
    acc.motion[2 * p] += o.mx;
    acc.motion[2 * p + 1] += o.my;
    const double lum = luminance(L);
    const int n = ++acc.n[p];
    const double delta = lum - acc.lum_mean[p];
    acc.lum_mean[p] += delta / n;
    acc.lum_m2[p] += delta * (lum - acc.lum_mean[p]);
  }
}

// ---- the renderer ------------------------------------------------------------------------------

Renderer::Renderer(const InstancedScene& scene, std::optional<Environment> environment) : impl_(new Impl) {
  Impl& r = *impl_;
  r.scene = &scene;
  const ValidationReport report = scene.validation();
  if (report.valid_triangle_count == 0)
    throw Error(ErrorCode::invalid_geometry, fmt::format("{}: no valid triangle to render ({})", r.source(), report.summary()));
  r.sync();  // the first sync: every previous transform is the current one
  r.choose_environment(std::move(environment));
}

Renderer::~Renderer() = default;
Renderer::Renderer(Renderer&&) noexcept = default;
Renderer& Renderer::operator=(Renderer&&) noexcept = default;

std::string Renderer::Impl::source() const { return scene->source().empty() ? "the scene" : scene->source(); }

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
    if (!m.material_ids.empty() && m.material_ids.size() != m.triangle_count())
      throw Error(ErrorCode::invalid_argument, fmt::format("{}: mesh '{}' has {} material ids for {} triangles", source(),
                                                           m.name, m.material_ids.size(), m.triangle_count()));
    for (uint32_t id : m.material_ids)
      if (id >= given)
        throw Error(ErrorCode::invalid_argument, fmt::format("{}: mesh '{}' names material {} of {}", source(), m.name, id, given));
    is.xf = s.transform(i);
    is.prev_xf = i < old.size() && old[i].mesh ? old[i].xf : is.xf;
    const Affine3 identity;
    is.identity = std::equal(std::begin(is.xf.m), std::end(is.xf.m), std::begin(identity.m)) &&
                  std::equal(std::begin(is.prev_xf.m), std::end(is.prev_xf.m), std::begin(identity.m));
    const Affine3 inv = inverse(is.xf);
    // inverse transpose of the linear part: row r of the result = column r of inv
    for (int row = 0; row < 3; ++row)
      for (int col = 0; col < 3; ++col) is.nrm[row * 3 + col] = inv.m[col * 4 + row];
  }
  sync_lights();
}

Bounds3 Renderer::bounds() const { return impl_->bounds; }
size_t Renderer::light_count() const { return impl_->lights.size(); }
const Environment& Renderer::environment() const { return impl_->env; }
void Renderer::set_capture(RayCapture* capture) { impl_->capture = capture; }

std::array<double, 3> Renderer::retrace(const RayCapture& c) const {
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

void frame_jitter(uint32_t index, float& jx, float& jy) {
  jx = radical_inverse(2, index + 1), jy = radical_inverse(3, index + 1);
}

namespace {

void check_render_settings(const Camera& camera, const RenderSettings& s, const std::optional<Camera>& prev_camera) {
  check_camera(camera);
  if (prev_camera) check_camera(*prev_camera);
  if (s.width <= 0 || s.height <= 0 || s.width > 32768 || s.height > 32768)
    throw Error(ErrorCode::invalid_argument, fmt::format("render: resolution {}x{} is out of range", s.width, s.height));
  if (s.spp <= 0) throw Error(ErrorCode::invalid_argument, fmt::format("render: spp must be positive, got {}", s.spp));
  if (s.max_depth <= 0) throw Error(ErrorCode::invalid_argument, fmt::format("render: max depth must be positive, got {}", s.max_depth));
  if (!(s.time_limit_s >= 0) || !(s.clamp >= 0)) throw Error(ErrorCode::invalid_argument, "render: time limit and clamp must be >= 0");
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
  frame.aov[int(Aov::variance)].pixels[p] = acc.n[p] > 1 ? float(acc.lum_m2[p] / (acc.n[p] - 1) / acc.n[p]) : 0.0f;
}

}  // namespace

int render_tile_size() { return tile_size; }

size_t render_tile_count(int width, int height) {
  return size_t((width + tile_size - 1) / tile_size) * size_t((height + tile_size - 1) / tile_size);
}

// One render over a list of tiles (every tile when `only` is null): passes outside, tiles
// inside, so each pixel sums its samples in pass order whichever tiles run together.
void Renderer::Impl::render_passes(const Camera& camera, const RenderSettings& s, const std::optional<Camera>& prev_camera,
                                   const std::vector<uint32_t>* only, Accumulator& acc, Frame& frame) {
  std::optional<ThreadLimit> limit;
  if (s.threads > 0 || capture) limit.emplace(capture ? 1 : s.threads);
  const CameraModel cam(camera, s.width, s.height);
  const CameraModel prev(prev_camera ? *prev_camera : camera, s.width, s.height);
  const int tiles_x = (s.width + tile_size - 1) / tile_size;
  const size_t tiles = only ? only->size() : render_tile_count(s.width, s.height);
  std::vector<double> tile_trace(tiles), tile_total(tiles);
  std::vector<std::array<uint64_t, 3>> tile_rays(tiles);
  const double start = now_ms();
  int passes = 0;
  std::atomic<size_t> tiles_done{0};
  for (int pass = 0; pass < s.spp; ++pass) {
    float jx = 0.5f, jy = 0.5f;
    if (s.jitter) frame_jitter(s.fixed_jitter ? s.frame : s.frame * uint32_t(s.spp) + uint32_t(pass), jx, jy);
    if (pass == 0) frame.jitter_x = jx, frame.jitter_y = jy;
    parallel_for(0, tiles, 1, [&](size_t b, size_t e) {
      for (size_t i = b; i < e; ++i) {
        const size_t t = only ? size_t((*only)[i]) : i;
        const double t0 = now_ms();
        uint64_t counts[3] = {0, 0, 0};
        double tms = 0;
        render_tile(cam, prev, s, int(t % size_t(tiles_x)), int(t / size_t(tiles_x)), pass, jx, jy, acc, tms, counts);
        tile_trace[i] += tms;
        tile_total[i] += now_ms() - t0;
        for (int k = 0; k < 3; ++k) tile_rays[i][size_t(k)] += counts[k];
        const size_t done = ++tiles_done;
        if (s.progress && (done % 16 == 0 || done == tiles * size_t(s.spp))) {
          const double f = double(done) / double(tiles * size_t(s.spp));
          const int bar = int(f * 40);
          std::fprintf(stderr, "\rrender [%.*s%*s] %5.1f%%  %.1f s", bar, "########################################",
                       40 - bar, "", 100 * f, (now_ms() - start) / 1000);
        }
      }
    });
    passes = pass + 1;
    if (s.time_limit_s > 0 && now_ms() - start >= s.time_limit_s * 1000) break;
  }
  if (s.progress) std::fprintf(stderr, "\n");
  frame.stats.ms += now_ms() - start;
  frame.stats.passes = passes;
  for (size_t t = 0; t < tiles; ++t) {
    frame.stats.trace_ms += tile_trace[t];
    frame.stats.total_thread_ms += tile_total[t];
    frame.stats.camera_rays += tile_rays[t][0];
    frame.stats.bounce_rays += tile_rays[t][1];
    frame.stats.shadow_rays += tile_rays[t][2];
  }
}

Frame Renderer::render(const Camera& camera, const RenderSettings& s, std::optional<Camera> prev_camera) {
  check_render_settings(camera, s, prev_camera);
  if (impl_->scene->generation() != impl_->generation) impl_->sync();
  Accumulator acc(s.width, s.height);
  Frame frame;
  impl_->render_passes(camera, s, prev_camera, nullptr, acc, frame);
  // Means of the sums.
  frame.width = s.width, frame.height = s.height;
  for (int a = 0; a < aov_count; ++a) frame.aov[a] = FloatImage(s.width, s.height, aov_channels(Aov(a)));
  for (size_t p = 0; p < size_t(s.width) * size_t(s.height); ++p) finish_pixel(acc, frame, p);
  return frame;
}

void Renderer::render_tiles(const Camera& camera, const RenderSettings& s, std::span<const uint32_t> tiles, Frame& frame,
                            std::optional<Camera> prev_camera) {
  check_render_settings(camera, s, prev_camera);
  if (s.time_limit_s > 0)
    throw Error(ErrorCode::invalid_argument, "render: a time limit cannot be split into tiles (every tile needs every pass)");
  const size_t count = render_tile_count(s.width, s.height);
  for (uint32_t t : tiles)
    if (t >= count) throw Error(ErrorCode::invalid_argument, fmt::format("render: tile {} of {}", t, count));
  if (impl_->scene->generation() != impl_->generation) impl_->sync();
  if (frame.width != s.width || frame.height != s.height) {
    frame = Frame{};
    frame.width = s.width, frame.height = s.height;
    for (int a = 0; a < aov_count; ++a) frame.aov[a] = FloatImage(s.width, s.height, aov_channels(Aov(a)));
  }
  auto& acc = impl_->tile_acc;
  if (!acc || acc->width != s.width || acc->height != s.height) acc = std::make_unique<Accumulator>(s.width, s.height);
  const int tiles_x = (s.width + tile_size - 1) / tile_size;
  auto for_pixels = [&](uint32_t t, auto&& f) {
    const int x0 = int(t % uint32_t(tiles_x)) * tile_size, y0 = int(t / uint32_t(tiles_x)) * tile_size;
    for (int y = y0; y < std::min(y0 + tile_size, s.height); ++y)
      for (int x = x0; x < std::min(x0 + tile_size, s.width); ++x) f(size_t(y) * size_t(s.width) + size_t(x));
  };
  for (uint32_t t : tiles)  // this render's sums start from zero, as render()'s
    for_pixels(t, [&](size_t p) {
      for (int c = 0; c < 3; ++c)
        acc->color[3 * p + size_t(c)] = acc->albedo[3 * p + size_t(c)] = acc->normal[3 * p + size_t(c)] = 0;
      acc->depth[p] = acc->rough[p] = acc->motion[2 * p] = acc->motion[2 * p + 1] = 0;
      acc->lum_mean[p] = acc->lum_m2[p] = 0;
      acc->n[p] = 0;
    });
  const std::vector<uint32_t> list(tiles.begin(), tiles.end());
  impl_->render_passes(camera, s, prev_camera, &list, *acc, frame);
  for (uint32_t t : tiles) for_pixels(t, [&](size_t p) { finish_pixel(*acc, frame, p); });
}

}  // namespace kestrel
