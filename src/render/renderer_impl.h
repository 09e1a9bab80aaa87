// The renderer's private state, shared by its files: renderer.cpp (the Renderer, passes and
// tiles, scene sync), integrator.cpp (the wavefront path tracer over a wave of tiles),
// lights.cpp (materials, area lights, NEE's light sample), environment.cpp (environment
// light), texture.cpp (texel fetches).
#pragma once
#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <unordered_map>
#include <vector>

#include "core/vec.h"
#include "kestrel/render.h"
#include "render/bsdf.h"
#include "render/light_tree.h"
#include "render/radiance_cache.h"
#include "render/sampling.h"
#include "render/surface_rows.h"
#include "render/testing.h"

namespace kestrel {

namespace render {

constexpr int tile_size = 32;
// Tiles traced together (render_wave): each bounce of a wave is one batch of up to
// wave_tiles x tile_size^2 rays. Fixed, so the waves (and the images) are the same for any
// thread count.
constexpr size_t wave_tiles = 256;
constexpr float specular_alpha =
    0.01f;  // surfaces below this alpha (and metallic) are "specular" for the AOVs
// Radiance cache: the first surface must be this rough (GGX alpha) for its bounce to stop at
// the cache (sharper reflections would show the cells), the second this rough for its
// radiance to be taken as the same towards every direction; 1 path in 16 trains the cache.
constexpr float cache_alpha_first = 0.1f, cache_alpha_second = 0.02f;
constexpr uint64_t cache_train_mask = 15;

/// Bilinear, repeat-wrapped texture fetch; sRGB-decoded per texel when `srgb` (texture.cpp).
void sample_texture(const Texture& tex, Vec2 uv, bool srgb, float out[3]);
// sample_texture's sRGB decoding: the linear value of each 8-bit code (256 floats).
const float* srgb_decode_table();
/// Texture coordinates at barycentrics (1 - b1 - b2, b1, b2) of a triangle; (0, 0) without uvs.
Vec2 uv_at(const TriangleMesh& m, uint32_t prim, float b1, float b2);
/// One channel (0..3), bilinear and repeat-wrapped as sample_texture, not decoded: [0, 1].
float sample_channel(const Texture& tex, Vec2 uv, int channel);
/// A texture's mean (sRGB-decoded) over a triangle's texture coordinates, by stratified samples.
Vec3 mean_texel(const Texture& tex, const TriangleMesh& m, uint32_t prim);

inline Vec3 normal_transform(const float n[9], Vec3 v) {
  return {n[0] * v.x + n[1] * v.y + n[2] * v.z, n[3] * v.x + n[4] * v.y + n[5] * v.z,
          n[6] * v.x + n[7] * v.y + n[8] * v.z};
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
      if (std::fabs(a) > std::fabs(b))
        r = a, phi = (pi / 4) * (b / a);
      else
        r = b, phi = pi / 2 - (pi / 4) * (a / b);
    }
    const Vec3 o =
        eye + right * (aperture * r * std::cos(phi)) + up * (aperture * r * std::sin(phi));
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

// A ray origin off the surface at p along its geometric normal n, scaled with p's magnitude.
inline Vec3 offset_origin(Vec3 p, Vec3 n) {
  const float scale = 1.0f + std::max({std::fabs(p.x), std::fabs(p.y), std::fabs(p.z)});
  return p + n * (2e-5f * scale);
}

// ---- ReSTIR DI's records (restir.cpp) ----
// A light sample that can be evaluated again at any surface: a local light (an emissive
// triangle's index with barycentrics (b1, b2) in v, or a punctual light's index) or a
// direction v towards the environment or the sun.
struct LightRef {
  static constexpr uint32_t env = 0xFFFFFFF0u, sun = 0xFFFFFFF1u;
  uint32_t id = invalid_id;
  Vec3 v{0, 0, 0};
};
// A reservoir: the sample kept, the sum of resampling weights, the candidates it stands for,
// its unbiased contribution weight W, and the target function at the surface it belongs to.
struct Reservoir {
  LightRef y;
  float w_sum = 0, M = 0, W = 0, p_hat = 0;
};
// What reuse needs of the first surface a camera ray hit.
struct RestirSurface {
  Vec3 p, ng, n, wo_l;  // n: shading normal (the BSDF's frame); wo_l: the view in that frame
  BsdfParams bp;
  float depth = 0;
  bool valid = false;
};
// What evaluating a light sample at a RestirSurface needs of it, computed once per surface
// rather than per sample (restir_eval): the shadow ray's origin, the shading frame and the
// BSDF at the view.
struct RestirShading {
  const RestirSurface& g;
  Vec3 origin;
  Basis frame;
  BsdfAt bsdf;
  explicit RestirShading(const RestirSurface& s)
      : g(s), origin(offset_origin(s.p, s.ng)), frame(s.n), bsdf(s.bp, s.wo_l, false) {}
};
// One pass's reservoirs and surfaces, image-wide: the next pass's (or frame's) history.
struct RestirBuffer {
  int width = 0, height = 0;
  std::vector<Reservoir> res;
  std::vector<RestirSurface> surf;
};
// What the path tracer needs for ReSTIR in one pass.
struct RestirPass {
  const RestirBuffer* prev = nullptr;  // null: no history
  RestirBuffer* cur = nullptr;
  bool same_camera = false;  // a later pass of the frame: history at the same pixel
};

inline double now_ms() {
  return std::chrono::duration<double, std::milli>(
             std::chrono::steady_clock::now().time_since_epoch())
      .count();
}

}  // namespace render

using namespace render;  // this private header's users are the renderer's own files

// What a path's first hit gives its pixel's AOVs.
struct PixelSample {
  Vec3 albedo{0, 0, 0}, normal{0, 0, 0};
  float depth = 0, roughness = 0, mx = 0, my = 0;
};

// Radiance scaled so that its largest component is at most `clamp` (0: off).
inline Vec3 clamped(Vec3 L, float clamp) {
  const float m = std::max({L.x, L.y, L.z});
  return clamp > 0 && m > clamp ? L * (clamp / m) : L;
}

struct Accumulator {
  int width, height;
  std::vector<float> color, albedo, normal, depth, rough, motion;  // sums
  std::vector<double> lum_mean, lum_m2;                            // Welford on luminance
  std::vector<int> n;
  /// A render of one pass: each pixel's sample goes straight into the frame's AOV images
  /// (their pixels here) as the mean of one sample (the same values; no sums to clear and
  /// divide). Empty otherwise.
  std::array<float*, aov_count> direct{};
  Accumulator(int w, int h) { reset(w, h); }
  /// Sums of w x h pixels at 0 (the storage kept: no page faults frame after frame; zeroed in
  /// parallel, 72 bytes a pixel, where it was the frame's serial part). renderer.cpp.
  void reset(int w, int h);
  /// One sample of pixel p (renderer.cpp).
  void add(size_t p, Vec3 L, const PixelSample& o, float clamp);
};

/// A hit as the shading code sees it: the scene's own InstanceHit (the instance; static scenes:
/// the mesh), so the trace batches write the shading's records directly.
using SurfaceHit = InstanceHit;

struct Renderer::Impl {
  struct InstanceShade {
    const TriangleMesh* mesh = nullptr;
    uint32_t mesh_key = 0;  // index into emissive_rank
    bool identity = true;
    bool colors = false;  // the mesh has a colour per vertex
    Affine3 xf, prev_xf;
    float nrm[9] = {1, 0, 0, 0, 1, 0, 0, 0, 1};  // inverse transpose of xf's linear part
    uint32_t light_base = 0;
  };
  struct LightTri {
    uint32_t instance, prim;
    Vec3 p0, e1, e2;
    float area;
    Vec3 normal;          // unit, of cross(e1, e2)
    const Material* mat;  // its material (materials outlive the lights: sync)
  };
  // The emission of light l at barycentrics (b1, b2).
  Vec3 light_emission(const LightTri& l, float b1, float b2) const {
    if (l.mat->emission_texture < 0) return l.mat->emission;
    const TriangleMesh& m = *instances[l.instance].mesh;
    return emission_at(*l.mat, uv_at(m, l.prim, b1, b2));
  }

  const InstancedScene* scene = nullptr;  // referenced: it outlives the renderer
  uint64_t generation = 0;                // the scene's commit the shading data are of
  std::vector<Material> materials;        // the scene's, plus a trailing "default"
  // Per material, its textures resolved (nullptr: none or unusable), so shading a hit does
  // not look them up: base colour, metallic-roughness, emission.
  // A material's textures, and its coat's F0 from its IOR, resolved once per render.
  struct MaterialMaps {
    const Texture *base = nullptr, *metallic_roughness = nullptr, *emission = nullptr;
    float f0 = 0.04f;  // ((ior - 1) / (ior + 1))^2; 0.04 exactly at glTF's IOR 1.5
  };
  std::vector<MaterialMaps> maps;  // maps[i] of materials[i] (each render_passes)
  const MaterialMaps& maps_of(const Material& m) const {
    return maps[size_t(&m - materials.data())];
  }
  std::vector<InstanceShade> instances;
  std::vector<std::vector<int32_t>> emissive_rank;  // per mesh key, per triangle: rank or -1
  // Punctual lights, or emitters whose emission is not from a texture: the scene's own
  // lighting, which turns the default sky off (sync_lights).
  bool lit_by_emitters = false;
  bool cutouts = false;  // a material is masked or blended (cutouts.cpp)
  // textured_emission's per-triangle means, per mesh, and what they were computed from.
  struct GlowCache {
    uint64_t key = 0;
    std::vector<float> mean;
    bool seen = false;
  };
  std::unordered_map<const TriangleMesh*, GlowCache> glow_cache;
  std::vector<LightTri> lights;  // emissive triangles: local lights 0 .. lights.size() - 1
  // Punctual lights (the scene's KHR_lights_punctual): local lights lights.size() .. on.
  struct Punctual {
    Light::Type type;
    Vec3 position, direction, intensity;  // intensity: colour x intensity
    float range, spot_scale, spot_offset;
  };
  std::vector<Punctual> punctual;
  Distribution1D light_dist;  // over the local lights, by power
  LightTree light_tree;       // over the same, when there is no directional light
  Environment env;
  bool env_on = false;
  bool env_cosine = true;  // env_sample cosine-weighted (constant, overcast, smooth sky)
  Distribution1D env_rows;
  std::vector<Distribution1D> env_cols;
  // A smooth sky's image box-filtered to at most 128 x 64 texels (RGB, rows of env_small_w),
  // looked up bilinearly without blending the hemispheres (env_smooth_radiance): it stays in
  // the caches where the full image's texel was a miss per light sample. Empty otherwise.
  std::vector<float> env_small;
  int env_small_w = 0, env_small_h = 0;
  float p_env = 0;  // probability NEE samples the environment
  // The sun (env.sun): a cone of directions sampled uniformly, radiance irradiance / solid angle.
  bool sun_on = false;
  Vec3 sun_dir, sun_radiance;
  Basis sun_frame{Vec3{0, 0, 1}};  // around sun_dir (sun_sample)
  float sun_cos_max = 1, sun_solid_angle = 0;
  float p_sun = 0;           // probability NEE samples the sun
  float env_irradiance = 0;  // luminance of the environment's irradiance on an upward surface
  bool env_ready = false;    // choose_environment ran (the probabilities can be set)
  Bounds3 bounds;
  RayCapture* capture = nullptr;
  bool surface_rows_on = true;            // surfaces in SIMD rows (off: surface_at, for tests)
  std::unique_ptr<Accumulator> tile_acc;  // render_tiles: sums kept between calls of one size
  Accumulator acc{0, 0};                  // render: the sums, storage kept from frame to frame
  RestirBuffer restir[2];                 // ReSTIR: [restir_last] is the last pass's
  int restir_last = 0;
  bool restir_valid = false;  // restir[restir_last] holds a pass of frame restir_frame
  uint32_t restir_frame = 0;
  RadianceCache radiance_cache;  // RenderSettings::radiance_cache
  bool cache_valid = false;      // radiance_cache holds passes up to frame cache_frame
  uint32_t cache_frame = 0;
  void render_passes(const Camera& camera, const RenderSettings& s,
                     const std::optional<Camera>& prev_camera, const std::vector<uint32_t>* only,
                     Accumulator& acc, Frame& frame);

  const Material& material_of(const TriangleMesh& m, uint32_t prim) const {
    const uint32_t id =
        prim < m.material_ids.size() ? m.material_ids[prim] : uint32_t(materials.size() - 1);
    return materials[std::min<size_t>(id, materials.size() - 1)];
  }
  const Texture* texture(int index) const {
    const std::vector<Texture>& textures = scene->textures();
    if (index < 0 || size_t(index) >= textures.size()) return nullptr;
    const Texture& t = textures[size_t(index)];
    return t.width > 0 && t.height > 0 && t.rgba.size() == size_t(t.width) * size_t(t.height) * 4
               ? &t
               : nullptr;
  }
  Vec3 emission_at(const Material& m, Vec2 uv) const {
    Vec3 e = m.emission;
    if (const Texture* t = maps_of(m).emission) {
      float px[4];
      sample_texture(*t, uv, true, px);
      e = e * Vec3{px[0], px[1], px[2]};
    }
    return e;
  }

  Vec3 env_radiance(Vec3 d) const {
    if (!env_on) return {0, 0, 0};
    if (env.image.pixels.empty()) {
      if (!env.overcast) return env.color * env.scale;
      const float cos_theta = d.y / std::sqrt(dot(d, d));
      return env.color *
             (env.scale * (cos_theta > 0 ? (1.0f + 2.0f * cos_theta) * (1.0f / 3.0f) : 0.1f));
    }
    const float u = 0.5f + atan2_fast(d.x, -d.z) * (1 / (2 * pi));
    const float v = acos_fast(std::clamp(d.y, -1.0f, 1.0f)) * (1 / pi);
    if (!env_small.empty()) return env_smooth_radiance(u, v, d.y >= 0.0f) * env.scale;
    const int x = std::clamp(int(u * float(env.image.width)), 0, env.image.width - 1);
    const int y = std::clamp(int(v * float(env.image.height)), 0, env.image.height - 1);
    const float* p = env.image.at(x, y);
    return Vec3{p[0], p[1], p[2]} * env.scale;
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

  // Probability (solid angle) that NEE at x picked this point on light triangle (instance,
  // prim), with the tree or by power.
  float light_pdf(uint32_t instance, uint32_t prim, float dist2, float cos_light, Vec3 x,
                  bool tree) const {
    if (lights.empty() || cos_light <= 0) return 0;
    const InstanceShade& is = instances[instance];
    const int32_t r = emissive_rank[is.mesh_key][prim];
    if (r < 0) return 0;
    const size_t li = is.light_base + size_t(r);
    return light_pdf_of(li, dist2, cos_light, tree ? light_tree.pmf(x, li) : light_dist.pmf(li));
  }
  // The same for light li picked with probability `pick` among the local lights (solid angle:
  // pick / area * distance^2 / cos).
  float light_pdf_of(size_t li, float dist2, float cos_light, float pick) const {
    const LightTri& l = lights[li];
    if (cos_light <= 0 || l.area <= 0) return 0;
    return (1 - p_env - p_sun) * pick / l.area * dist2 / cos_light;
  }
  size_t local_light_count() const { return lights.size() + punctual.size(); }
  // The sun's radiance towards d (unit) when d is inside its disk.
  Vec3 sun_radiance_towards(Vec3 d) const {
    return sun_on && dot(d, sun_dir) >= sun_cos_max ? sun_radiance : Vec3{0, 0, 0};
  }

  // environment.cpp
  void choose_environment(std::optional<Environment> environment);
  void setup_environment();
  void choose_strategies();  // p_env, p_sun from what there is to sample
  float env_pdf(Vec3 d, Vec3 n) const;
  // env_small at (u, v) of the equirectangular map, bilinear (u wraps), rows of the upper
  // hemisphere only when `upper`, else of the lower one.
  Vec3 env_smooth_radiance(float u, float v, bool upper) const;
  Vec3 env_sample(float u1, float u2, Vec3 n, float& pdf) const;
  // lights.cpp
  void check_materials(const std::string& source);
  void sync_lights();
  const std::vector<float>& textured_emission(const TriangleMesh& mesh, uint64_t glow_key);
  // renderer.cpp
  std::string source() const;
  void sync();
  // cutouts.cpp: the scene's queries, through surfaces a material's alpha leaves out.
  void trace(std::span<const Ray> rays, std::span<SurfaceHit> hits) const;
  void occluded(std::span<const Ray> rays, std::span<uint8_t> out) const;
  void pass_cutouts(std::span<const Ray> rays, std::span<SurfaceHit> hits) const;
  bool cut_out(const Ray& ray, const SurfaceHit& h) const;
  // integrator.cpp
  struct Surface {
    Vec3 p, p_obj, ng, ns, wo;
    float cos_hit = 0, roughness = 0;
    Vec2 uv;
    const Material* mat = nullptr;
    BsdfParams bp;
  };
  Surface surface_at(const SurfaceHit& h, const Ray& ray) const;
  void normal_map(const SurfaceHit& h, Surface& sf) const;
  // The mesh's vertex colours at the hit times the base colour (after surface_material).
  void vertex_colors(const SurfaceHit& h, Surface& sf) const;
  // surface_at's first part: p, p_obj, wo, ng (facing wo), cos_hit, the material.
  void surface_geometry(const SurfaceHit& h, const Ray& ray, Surface& sf) const;
  // surface_at of a hit from its entry j of SIMD rows (render/surface_rows.h: the same
  // values), and its last part: the material's BSDF parameters and roughness at sf.uv.
  Surface surface_from_rows(const render::SurfaceRows& rows, int j, const SurfaceHit& h,
                            const Ray& ray) const;
  void surface_material(Surface& sf, const float* texel = nullptr) const;  // texel: its base one
  // The rows of a group of n <= SurfaceRows::size hits (rays[j] is hit j's): the lanes on the
  // first hit's instance; bit j set where entry j is hit j's.
  // `texels`: with the base texels of the lanes that share the first textured lane's texture
  // (worth it where neighbouring hits read neighbouring texels: camera rays').
  uint32_t surface_rows_of(const render::SurfaceRowsKernels& kernels, const SurfaceHit* hits,
                           const Ray* rays, size_t n, bool texels, render::SurfaceRows& rows) const;
  // A bounce's hits' surfaces in SIMD rows, a group of SurfaceRows::size at a time, one group
  // ahead of the shading loop: group g + 1 is made as the loop reaches hit 16 g, by when the
  // loop's prefetches have fetched its vertices (surface.cpp).
  class SurfaceGroups {
   public:
    // `kernels`: the wave's (WavePass::rows; null: every hit by surface_at). `texels`: with the
    // groups' base texels (surface_rows_of). `rngs`, `active`: the paths' generators and hit
    // k's path, for each group's draws (PathDraws; null: none).
    SurfaceGroups(const Impl& r, const render::SurfaceRowsKernels* kernels,
                  std::span<const SurfaceHit> hits, const Ray* rays, bool texels,
                  const Rng* rngs = nullptr, const uint32_t* active = nullptr);
    // The loop reached hit k: at the start of a group, the next one is made.
    void reached(size_t k) {
      if (k % group == 0 && k > 0) make(k / group + 1);
    }
    // Hit k's rows and its entry j there, or null (its surface from surface_at).
    const render::SurfaceRows* rows_of(size_t k, int& j) const {
      j = int(k % group);
      const size_t slot = (k / group) & 1;
      return (in_rows_[slot] >> j) & 1u ? &rows_[slot] : nullptr;
    }
    // Hit k's path's next light-sample draws (entry j), made from its generator as it is
    // while nothing else draws from it, or null.
    const render::PathDraws* draws_of(size_t k, int& j) const {
      j = int(k % group);
      const size_t slot = (k / group) & 1;
      return drawn_[slot] ? &draws_[slot] : nullptr;
    }

   private:
    static constexpr size_t group = render::SurfaceRows::size;
    void make(size_t g);
    const Impl& r_;
    std::span<const SurfaceHit> hits_;
    const Ray* rays_;
    bool texels_;
    const render::SurfaceRowsKernels* kernels_;  // null: surface_rows_on is off
    render::SurfaceRows rows_[2];
    uint32_t in_rows_[2] = {0, 0};
    const Rng* rngs_;
    const uint32_t* active_;
    Vec3 sun_basis_[3];
    render::PathDraws draws_[2];
    bool drawn_[2] = {false, false};
  };
  // The material's roughness in [0, 1] at uv (its metallic-roughness texture's G scales it)
  // and its metallic factor (the texture's B); uv_of() is asked only where there is a texture.
  template <class Uv>
  float roughness_at(const Material& mat, Uv&& uv_of, float& metallic) const {
    float roughness = mat.roughness;
    metallic = mat.metallic;
    if (const Texture* t = maps_of(mat).metallic_roughness) {
      float c[3];
      sample_texture(*t, uv_of(), false, c);
      roughness *= c[1];
      metallic *= c[2];
    }
    metallic = std::clamp(metallic, 0.0f, 1.0f);
    return std::clamp(roughness, 0.0f, 1.0f);
  }
  bool cache_answer(const SurfaceHit& h, const RadianceCache::Cell& cell, Vec3& lc) const;
  RadianceCache::Cell cache_cell(const SurfaceHit& h, const Ray& ray) const;
  RadianceCache::Cell cache_cell(const render::SurfaceRows& rows, int j) const;  // the same
  // `env`: the environment among the lights to pick (else the sun and the local lights, their
  // probabilities scaled by nee_scale(false)).
  // `pre`: the path's draws made ahead (SurfaceGroups::draws_of, entry j) or null: from rng.
  // (origin and throughput by reference: passed by value, each was stored to the stack a
  // float at a time and reloaded as two registers, a store-forwarding stall on every call.)
  bool sample_light(const Surface& sf, const Basis& frame, const BsdfAt& bsdf, const Vec3& origin,
                    const Vec3& throughput, Rng& rng, bool tree, bool env, Ray& shadow,
                    Vec3& contribution, const render::PathDraws* pre = nullptr, int j = 0) const;
  // A Lambertian BSDF is sampled with the cosine, the density with which a cosine-sampled
  // environment (env_cosine) is: a light sample of the environment there would draw what the
  // BSDF sample draws, for the price of a shadow ray (inside Sponza the sky's rays cost ~5
  // times the sun's, which trace as packets). Where the sun outshines the environment (NEE
  // picks it at least as often: by irradiance), NEE at such a surface picks among the sun and
  // the local lights alone and the BSDF sample carries the environment (MIS weight 1): the
  // sun is never missed for a sky sample. Both stay unbiased.
  bool env_left_to_bsdf(const BsdfParams& bp) const {
    return env_cosine && p_env > 0 && p_env <= p_sun && bp.metallic <= 0 && bp.specular <= 0 &&
           bp.transmission <= 0;
  }
  // The factor on the sun's and the local lights' pick probabilities where NEE left the
  // environment out (env false).
  float nee_scale(bool env) const { return env ? 1.0f : 1.0f / (1.0f - p_env); }
  // A punctual light seen from origin: direction, the ray's vector and end, radiance x falloff.
  bool punctual_light(const Punctual& q, Vec3 origin, Vec3& wi, Vec3& dir, Vec3& le,
                      float& tmax) const;
  Vec3 sun_sample(float u1, float u2) const;  // uniform in the sun's cone
  // restir.cpp
  bool restir_eligible(const Surface& sf) const;
  struct LightDraw {
    LightRef y;
    float pdf;  // of NEE's local-light strategy at the origin it was drawn for, y's measure
  };
  // One local light by NEE's choice (tree or power) at origin, a point on it by u1, u2.
  LightDraw local_light_sample(Vec3 origin, bool tree, float u, float u1, float u2) const;
  // local_light_sample(origin, tree, u[i], u1[i], u2[i]) into out[i] for n draws at one
  // origin (the light tree's walks advance together).
  void local_light_samples(Vec3 origin, bool tree, const float* u, const float* u1, const float* u2,
                           size_t n, LightDraw* out) const;
  // Local light li, picked with probability pick, and a point on it by u1, u2.
  LightDraw local_light_draw(size_t li, float pick, float u1, float u2) const;
  // Unshadowed f * Le * G of y at g, in the measure y was sampled in (area for emissive
  // triangles, solid angle for directions, counting for punctual lights); the shadow ray.
  Vec3 restir_eval(const RestirShading& g, const LightRef& y, Ray* shadow) const;
  // luminance(restir_eval(g, y, nullptr)): the target function ReSTIR resamples by.
  float restir_target(const RestirShading& g, const LightRef& y) const;
  // restir_eval's light part from the shadow ray's origin: direction, shadow-ray direction
  // and length, radiance, G.
  bool restir_light(Vec3 origin, const LightRef& y, Vec3& wi, Vec3& dir, Vec3& le, float& geometry,
                    float& tmax) const;
  // The shadow ray restir_eval(g, y, &ray) gives where it gives light, without the BSDF.
  Ray restir_shadow_ray(const RestirSurface& g, const LightRef& y) const;
  Vec3 restir_eval(const RestirSurface& g, const LightRef& y, Ray* shadow) const {
    return restir_eval(RestirShading(g), y, shadow);
  }
  // The initial reservoirs of a tile's pixels: per 4 x 4 block, a pool of samples of NEE's
  // strategies at one surface of the block (light presampling); each pixel resamples
  // s.restir_candidates of its block's pool by p_hat.
  void restir_candidates(const RenderSettings& s, int x0, int y0, int w, int h, int pass, bool tree,
                         std::span<const RestirSurface> surf, std::span<Reservoir> res,
                         std::span<Rng> rngs) const;
  // Temporal then spatial reuse over one tile (w x h pixels at x0, y0); res: the initial
  // reservoirs in, the final ones out; prev_pixel: the pixel of the history (or -1).
  void restir_reuse(const RestirPass& rp, const RenderSettings& s, int x0, int y0, int w, int h,
                    std::span<Reservoir> res, std::span<const RestirSurface> surf,
                    std::span<const int32_t> prev_pixel, std::span<Rng> rngs) const;
  void prefetch_indices(const SurfaceHit& h) const;
  void prefetch_vertices(const SurfaceHit& h) const;
  void prefetch_texels(const SurfaceHit& h) const;
  void prefetch_texels(const SurfaceHit& h, Vec2 uv) const;  // its texture coordinates known
  // integrator.cpp: the path tracer over a wave of tiles.
  struct WavePass {  // what every tile of a wave shares
    const CameraModel& cam;
    const CameraModel& prev_cam;
    const RenderSettings& s;
    const RestirPass* rp;
    int pass;
    float jx, jy;
    bool use_tree;
    const render::SurfaceRowsKernels* rows;  // null: surface_rows_on is off
  };
  // A tile's camera rays in 4 x 4 blocks of pixels (path k is pixel active[k] of the tile,
  // rays and active of its pixel count) and its paths' generators (camera_paths.cpp).
  static void camera_paths(const WavePass& wp, int x0, int y0, int x1, int y1,
                           std::vector<render::Rng>& rngs, std::vector<Ray>& rays,
                           std::vector<uint32_t>& active);
  struct TilePaths;
  struct Wave;
  struct WaveDelete {
    void operator()(Wave* w) const;
  };
  struct WaveStats {
    double trace_ms = 0;           // in trace()/occluded(), wall time x threads
    double thread_ms = 0;          // in render_wave, wall time x threads
    uint64_t rays[3] = {0, 0, 0};  // camera, bounce, shadow
    RenderStats::Steps steps;      // wall ms
  };
  std::unique_ptr<Wave, WaveDelete> wave;  // the wave's storage, kept between renders
  size_t tiles_per_wave = wave_tiles;      // RendererTesting::set_wave_tiles
  void render_wave(const WavePass& wp, std::span<const uint32_t> ids, int tiles_x,
                   std::vector<CacheRecord>* records, Accumulator& acc, WaveStats& stats);
};

}  // namespace kestrel
