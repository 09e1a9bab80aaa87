// The path tracer, wavefront over a wave of tiles: each tile's paths advance one bounce at a
// time, and each bounce's rays of all the wave's tiles are one batch for trace() (camera rays
// as coherent packets, bounces as ray streams where the batch API finds them faster) and one
// for occluded() (the next-event shadow rays); shading runs per tile between the batches.
// Per-sample random streams are seeded from (seed, frame, pixel, sample), tiles write disjoint
// pixels and every ray's hit is the same in any batch, so the image does not depend on threads
// or on how the tiles are grouped.
#include <algorithm>
#include <cmath>

#include "core/parallel.h"
#include "render/bsdf.h"
#include "render/renderer_impl.h"

namespace kestrel {

using namespace render;

namespace {

// One cache line: the shading loop touches it per path per bounce (the path's pixel is its
// index in the tile's arrays; the radiance cache's vertex, rarely touched, is in CacheVertex).
struct alignas(64) PathState {
  Vec3 throughput{1, 1, 1}, radiance{0, 0, 0};
  float bsdf_pdf = 0;         // pdf of the direction that led here (solid angle)
  Vec3 prev_normal{0, 0, 1};  // shading normal where that direction was sampled
  bool aov_pending = true;
  // Whether NEE at the vertex this ray left could pick the environment (env_left_to_bsdf):
  // the MIS weights of what the ray hits use that vertex's light choice.
  bool env_nee = true;
  bool restir = false;   // the first hit's direct light came from ReSTIR: BSDF rays skip it
  bool through = false;  // went through glass (NEE draws nothing below): MIS weight 1
  // Radiance cache: a training path never stops at the cache; rough: the surface the last
  // bounce left may use it; cache_key: the first bounce's cell (its CacheVertex holds the
  // path's radiance and throughput there).
  bool train = true, rough = false;
  uint64_t cache_key = 0;
};
static_assert(sizeof(PathState) == 64);

// A path's radiance and throughput at its radiance-cache vertex: its outgoing radiance there
// is what the path adds after it, / throughput.
struct CacheVertex {
  Vec3 radiance, throughput;
};

struct Shadow {
  Vec3 contribution;
  uint32_t path;
};

constexpr size_t index_distance = 64, vertex_distance = 40, texel_distance = 12,
                 state_distance = 24;

// The outgoing radiance a path measured at its cached vertex, clamped as samples are.
bool cache_sample(const PathState& ps, const CacheVertex& cv, float clamp, Vec3& out) {
  const Vec3 t = cv.throughput, d = ps.radiance - cv.radiance;
  if (!(t.x > 0 && t.y > 0 && t.z > 0)) return false;
  out = {d.x / t.x, d.y / t.y, d.z / t.z};
  if (!is_finite(out)) return false;
  out = clamped(max(out, Vec3{0, 0, 0}), clamp);
  return true;
}

// What a solid's medium (Material::attenuation_*) lets through along a distance t inside it.
Vec3 absorption(const Material& m, float t) {  // (t > 0; a colour of 0 keeps nothing)
  Vec3 out;
  for (int k = 0; k < 3; ++k)
    out[k] =
        std::exp(std::log(std::min(m.attenuation_color[k], 1.0f)) / m.attenuation_distance * t);
  return out;
}

}  // namespace

// Whether pixel (x, y)'s path goes on after its first hit in frame `frame` at the given
// indirect rate: 0.5 a checkerboard, 0.25 one pixel of each 2x2 block, both cycling with the
// frame so that every pixel goes on once in 1 / rate frames.
static bool first_bounce_survives(uint32_t x, uint32_t y, uint32_t frame, float rate) {
  if (rate >= 1.0f) return true;
  if (rate >= 0.5f) return ((x + y + frame) & 1u) == 0;
  static constexpr uint32_t order[4] = {0, 3, 1, 2};  // (0,0) (1,1) (1,0) (0,1)
  return ((x & 1u) | ((y & 1u) << 1)) == order[frame & 3u];
}

// ---- one tile's paths ----------------------------------------------------------------------

// One tile's paths through a pass, a bounce at a time: its rays of the bounce, the shadow rays
// of the bounce's next-event estimation, ReSTIR's reservoirs. Between the steps the wave traces
// the rays of all its tiles as one batch. The storage is kept from pass to pass.
struct Renderer::Impl::TilePaths {
  const WavePass* ctx = nullptr;
  std::vector<CacheRecord>* cache_records = nullptr;
  int x0 = 0, y0 = 0, x1 = 0, y1 = 0;
  size_t count = 0;
  std::vector<Rng> rngs;
  std::vector<PathState> paths;
  std::vector<CacheVertex> cache_vtx;  // of paths with a cache_key
  std::vector<PixelSample> px;
  std::vector<Ray> rays, next_rays;
  std::vector<uint32_t> active, next_active;
  std::vector<RadianceCache::Cell> cells;  // of hits the radiance cache likely answers, else key 0
  // Next-event shadow rays, each with what it adds when unblocked: the first hits' towards the
  // sun's cone (near-parallel: the wave traces them as packets) apart from the rest.
  std::vector<Ray> sun_rays, shadow_rays;
  std::vector<Shadow> sun_shadows, shadows;
  // ReSTIR: per pixel of the tile, the reservoir, the surface and the history's pixel; the
  // visibility rays of the initial reservoirs (biased mode) and their pixels.
  std::vector<Reservoir> rres;
  std::vector<RestirSurface> rsurf;
  std::vector<int32_t> rprev;
  std::vector<Ray> vis;
  std::vector<uint32_t> vis_pixel;

  // The tile's camera rays.
  void begin(const WavePass& wp, int tx, int ty, std::vector<CacheRecord>* records);
  // Shades the bounce's hits (one per ray, in order): the next bounce's rays, the shadow rays.
  void shade(const Impl& r, int depth, std::span<const SurfaceHit> hits);
  // ReSTIR after the first hits: the initial reservoirs and their visibility rays (vis) ...
  void restir_initial(const Impl& r);
  // ... whose results (one per vis ray) drop blocked samples before reuse; the shadow rays of
  // the reservoirs' samples.
  void restir_final(const Impl& r, std::span<const uint8_t> blocked);
  // The shadow rays' results (one per ray of sun_rays, then of shadow_rays): the unblocked
  // add their light; the next bounce.
  void finish_bounce(std::span<const uint8_t> sun_blocked, std::span<const uint8_t> blocked);
  // Adds the tile's samples to the sums (and the radiance cache's records).
  void end(Accumulator& acc) const;
};

void Renderer::Impl::TilePaths::begin(const WavePass& wp, int tx, int ty,
                                      std::vector<CacheRecord>* records) {
  ctx = &wp;
  cache_records = records;
  const RenderSettings& s = wp.s;
  x0 = tx * tile_size, y0 = ty * tile_size;
  x1 = std::min(x0 + tile_size, s.width), y1 = std::min(y0 + tile_size, s.height);
  count = size_t(x1 - x0) * size_t(y1 - y0);
  paths.resize(count);  // each path and pixel sample set at its first hit (shade, depth 0):
  px.resize(count);     // written where they are read next, not twice
  cache_vtx.resize(records ? count : 0);
  rays.resize(count);
  active.resize(count);
  const size_t restir_count = wp.rp ? count : 0;
  rres.assign(restir_count, Reservoir{});
  rsurf.assign(restir_count, RestirSurface{});
  rprev.assign(restir_count, -1);
  camera_paths(wp, x0, y0, x1, y1, rngs, rays, active);
}

void Renderer::Impl::TilePaths::shade(const Impl& r, int depth, std::span<const SurfaceHit> hits) {
  const RenderSettings& s = ctx->s;
  const CameraModel &cam = ctx->cam, &prev_cam = ctx->prev_cam;
  const RestirPass* rp = ctx->rp;
  const bool use_tree = ctx->use_tree;
  const size_t n = active.size();
  // A camera ray's path and pixel sample (of pixel k of the tile).
  const auto start = [&](size_t k) {
    PathState& ps = paths[k];
    ps = PathState{};
    const uint32_t tw = uint32_t(x1 - x0), kk = uint32_t(k);  // (32-bit divisions)
    const int x = x0 + int(kk % tw), y = y0 + int(kk / tw);
    const uint64_t pixel = uint64_t(y) * uint64_t(s.width) + uint64_t(x);
    ps.train =
        !cache_records ||
        (mix64(s.seed ^ mix64(pixel ^ mix64(uint64_t(s.frame) << 20 ^ uint64_t(ctx->pass)))) &
         cache_train_mask) == 0;
    px[k] = PixelSample{};
  };
  // The MIS weight (power heuristic) of light a BSDF-sampled ray found, against the density
  // lp with which NEE at the vertex it left could have sampled it; after a first hit whose
  // direct light was ReSTIR's, what ReSTIR could sample it has (weight 0).
  const auto bsdf_weight = [depth](const PathState& ps, float lp) {
    if (ps.through) return 1.0f;
    return ps.restir && depth == 1
               ? (lp > 0 ? 0.0f : 1.0f)
               : ps.bsdf_pdf * ps.bsdf_pdf / (ps.bsdf_pdf * ps.bsdf_pdf + lp * lp);
  };
  next_rays.clear();
  next_active.clear();
  sun_rays.clear();
  sun_shadows.clear();
  shadow_rays.clear();
  shadows.clear();
  // Shading reads scattered vertex data: fetch it ahead, indices first, then the vertices
  // they name, then texels (misses overlap instead of stalling one hit at a time).
  for (size_t k = 0; k < std::min(n, index_distance); ++k) r.prefetch_indices(hits[k]);
  for (size_t k = 0; k < std::min(n, vertex_distance); ++k) r.prefetch_vertices(hits[k]);
  // The hits' surfaces in SIMD rows a group ahead of the loop; the first hits' base texels too
  // (bounce hits' texels are scattered, and most of them the radiance cache answers without).
  // The first hits' path draws too (at bounces the radiance cache answers most hits before
  // any draw, and their generators are scattered: there they cost more than they saved).
  SurfaceGroups surfaces(r, ctx->rows, hits, rays.data(), depth == 0,
                         depth == 0 ? rngs.data() : nullptr, active.data());
  // Paths the radiance cache likely answers at their second vertex: their cell (its slot
  // prefetched) instead of texels.
  const bool cache_stops = cache_records && depth == 1 && depth + 1 < s.max_depth;
  cells.resize(n);
  auto ahead = [&](size_t k) {
    const PathState& q = paths[active[k]];
    cells[k].key = 0;
    int j;
    const SurfaceRows* row = surfaces.rows_of(k, j);
    if (!(cache_stops && q.rough && !q.train && !q.aov_pending)) {
      if (!row)
        r.prefetch_texels(hits[k]);
      else if (!((row->texel >> j) & 1u))  // (a base texel in the rows is fetched already)
        r.prefetch_texels(hits[k], Vec2{row->u[j], row->v[j]});
    } else if (hits[k].hit()) {
      cells[k] = row ? r.cache_cell(*row, j) : r.cache_cell(hits[k], rays[k]);
    }
  };
  for (size_t k = 0; k < std::min(n, texel_distance); ++k) ahead(k);
  for (size_t k = 0; k < n; ++k) {
    surfaces.reached(k);
    if (k + index_distance < n) r.prefetch_indices(hits[k + index_distance]);
    if (k + vertex_distance < n) r.prefetch_vertices(hits[k + vertex_distance]);
    if (k + texel_distance < n) ahead(k + texel_distance);
    // The path's state a few paths ahead (the wave's trace between bounces evicted the
    // tile's arrays; a path's pixel sample has the path's index).
    if (k + state_distance < n) {
      const uint32_t a = active[k + state_distance];
      __builtin_prefetch(&paths[a], 1);
      __builtin_prefetch(&rngs[a], 1);
      __builtin_prefetch(&px[a], 1);
    }
    const uint32_t pix = active[k];  // the path's pixel in the tile
    PathState& ps = paths[pix];
    Rng& rng = rngs[pix];
    if (depth == 0) start(pix);
    PixelSample& out = px[pix];
    const Ray& ray = rays[k];
    const SurfaceHit& h = hits[k];
    if (!h.hit()) {
      const Vec3 le = r.env_radiance(ray.dir);
      float w = 1;
      if (depth > 0 && r.p_env > 0) {
        const float lp = ps.env_nee ? r.p_env * r.env_pdf(ray.dir, ps.prev_normal) : 0.0f;
        w = bsdf_weight(ps, lp);
      }
      ps.radiance = ps.radiance + ps.throughput * le * w;
      if (r.sun_on) {  // a ray that escapes into the sun's disk
        const Vec3 ls = r.sun_radiance_towards(normalize(ray.dir));
        if (luminance(ls) > 0) {
          float ws = 1;
          if (depth > 0) {
            const float lp = r.p_sun / r.sun_solid_angle * r.nee_scale(ps.env_nee);
            ws = bsdf_weight(ps, lp);
          }
          ps.radiance = ps.radiance + ps.throughput * ls * ws;
        }
      }
      if (ps.aov_pending) {
        out.albedo = min(le, Vec3{1, 1, 1});
        out.normal = {0, 0, 0};
        out.roughness = 0;
      }
      continue;
    }
    // A path the radiance cache stops at its second vertex needs no more shading.
    if (cells[k].key != 0) {
      Vec3 lc;
      if (r.cache_answer(h, cells[k], lc)) {
        ps.radiance = ps.radiance + ps.throughput * lc;
        continue;
      }
    }
    // Surface interaction.
    const InstanceShade& is = r.instances[h.instance_id];
    int row_j;
    const SurfaceRows* row = surfaces.rows_of(k, row_j);
    const Surface sf = row ? r.surface_from_rows(*row, row_j, h, ray) : r.surface_at(h, ray);
    const Vec3 &p = sf.p, &ng = sf.ng, &ns = sf.ns, &wo = sf.wo;
    const Material& mat = *sf.mat;
    const BsdfParams& bp = sf.bp;
    // A ray that reached a solid glass's far side crossed it: its absorption (Beer-Lambert).
    if (bp.transmission > 0 && sf.cos_hit < 0 && !bp.thin && mat.attenuation_distance < INFINITY)
      ps.throughput = ps.throughput * absorption(mat, h.t);
    if (depth == 0) {
      out.depth = dot(p - cam.eye, cam.forward);
      const Vec3 p_prev = is.identity ? p : is.prev_xf.point(sf.p_obj);
      float fx, fy, gx, gy;
      if (cam.project(p, fx, fy) && prev_cam.project(p_prev, gx, gy)) {
        out.mx = gx - fx, out.my = gy - fy;
        if (rp && !rp->same_camera && gx >= 0 && gy >= 0 && gx < float(s.width) &&
            gy < float(s.height))
          rprev[pix] = int32_t(int(gy) * s.width + int(gx));
      }
      if (rp && rp->same_camera) {
        const size_t i = pix;
        rprev[i] = int32_t((y0 + int(i) / (x1 - x0)) * s.width + x0 + int(i) % (x1 - x0));
      }
    }
    const bool specular_surface =
        (bp.metallic >= 0.5f || bp.transmission >= 0.5f) && bp.alpha < specular_alpha;
    if (ps.aov_pending) {
      out.albedo = bp.base;
      out.normal = ns;
      out.roughness = sf.roughness;
      if (!specular_surface || depth >= 3) ps.aov_pending = false;
    }
    // Emission (two-sided), weighted against light sampling.
    if (luminance(mat.emission) > 0) {
      const Vec3 le = r.emission_at(mat, sf.uv);
      float w = 1;
      if (depth > 0) {
        const float lp = r.light_pdf(h.instance_id, h.prim_id, h.t * h.t, std::fabs(sf.cos_hit),
                                     ray.org, use_tree) *
                         r.nee_scale(ps.env_nee);
        w = bsdf_weight(ps, lp);
      }
      ps.radiance = ps.radiance + ps.throughput * le * w;
    }
    if (depth + 1 >= s.max_depth) continue;
    // Radiance cache at the first bounce's surface: stop there with its cell's radiance
    // (when the bounce is longer than a cell: contact light needs the path), or note the
    // vertex so this path teaches the cell what it measures from here on.
    if (cache_records && depth == 1 && ps.rough && bp.alpha >= cache_alpha_second &&
        !(bp.transmission > 0)) {
      const RadianceCache::Cell cell =  // found ahead where the cache was to answer
          cells[k].key != 0 ? cells[k] : r.radiance_cache.cell(p, ng);
      Vec3 lc;
      if (!ps.train && h.t >= cell.size && r.radiance_cache.lookup(cell.key, lc)) {
        ps.radiance = ps.radiance + ps.throughput * lc;
        continue;
      }
      ps.cache_key = cell.key;
      cache_vtx[pix] = {ps.radiance, ps.throughput};
    }
    const Basis frame(ns);
    const Vec3 wo_l = frame.to_local(wo);
    const BsdfAt bsdf(bp, wo_l);
    const bool env_nee = !r.env_left_to_bsdf(bp);
    const Vec3 origin = offset_origin(p, ng);
    // Next-event estimation: one light sample (an emissive triangle or the environment),
    // or at the first hit ReSTIR's reservoir (shaded once the tile's reuse is done). `pre`:
    // the path's draws made ahead, once the light sample has taken its three.
    const PathDraws* pre = nullptr;
    int dj = 0;
    if (rp && depth == 0 && r.restir_eligible(sf)) {
      RestirSurface& g = rsurf[pix];
      g = {sf.p, ng, ns, wo_l, bp, out.depth, true};
      ps.restir = true;  // its reservoir comes after the loop, from its block's pool
    } else if (r.p_env > 0 || r.p_sun > 0 || r.local_light_count() > 0) {
      Ray shadow;
      Vec3 contribution;
      pre = surfaces.draws_of(k, dj);
      if (r.sample_light(sf, frame, bsdf, origin, ps.throughput, rng, use_tree, env_nee, shadow,
                         contribution, pre, dj)) {
        // From a first hit towards the sun's cone: with the tile's others of its kind, a run
        // of near-parallel rays from neighbouring points (from bounce hits, whose points are
        // scattered, they stay with the rest: as packets they were no faster).
        const bool parallel = depth == 0 && shadow.tmax == INFINITY && r.sun_on &&
                              dot(shadow.dir, r.sun_dir) >= r.sun_cos_max;
        (parallel ? sun_rays : shadow_rays).push_back(shadow);
        (parallel ? sun_shadows : shadows).push_back({contribution, active[k]});
      }
    }
    // Russian roulette at the first bounce (indirect_rate < 1): the pixels whose turn it is
    // not stop here with their direct light; mirror-like surfaces always go on.
    if (depth == 0 && s.indirect_rate < 1.0f && !specular_surface) {
      const uint32_t px_x = uint32_t(x0 + int(pix % uint32_t(x1 - x0)));
      const uint32_t px_y = uint32_t(y0 + int(pix / uint32_t(x1 - x0)));
      if (!first_bounce_survives(px_x, px_y, s.frame + uint32_t(ctx->pass), s.indirect_rate))
        continue;
      ps.throughput = ps.throughput * (1.0f / s.indirect_rate);
    }
    // Continue the path by sampling the BSDF (with the next three draws, made ahead where the
    // light sample took the three before them).
    BsdfSample bs;
    if (pre) {
      rng.set_state(pre->state6[dj]);
      const Vec3 cosine{pre->cx[dj], pre->cy[dj], pre->cz[dj]};
      if (!bsdf.sample(pre->b0[dj], pre->b1[dj], pre->b2[dj], &cosine, bs)) continue;
    } else {
      const float u0 = rng.uniform(), u1 = rng.uniform(), u2 = rng.uniform();
      if (!bsdf.sample(u0, u1, u2, nullptr, bs)) continue;
    }
    const Vec3 wi = frame.to_world(bs.wi);
    const bool through = bs.wi.z < 0;  // through glass: on the far side of the surface
    if (through ? !(dot(wi, ng) < 0) : !(dot(wi, ng) > 0)) continue;
    ps.throughput = ps.throughput * bs.weight;
    ps.bsdf_pdf = bs.pdf;
    ps.prev_normal = ns;
    ps.env_nee = env_nee;
    ps.through = through;
    ps.rough = bp.alpha >= cache_alpha_first && !(bp.transmission > 0);
    if (depth + 1 >= s.rr_depth) {
      const float q =
          std::min(0.95f, std::max({ps.throughput.x, ps.throughput.y, ps.throughput.z}));
      if (!(rng.uniform() < q)) continue;
      ps.throughput = ps.throughput * (1.0f / q);
    }
    next_rays.push_back(Ray{through ? offset_origin(p, -ng) : origin, wi, 0.0f, INFINITY});
    next_active.push_back(active[k]);
  }
}

// ReSTIR: visibility reuse (the biased mode drops initial samples that are blocked), temporal
// and spatial reuse, then one shadow ray per pixel for the reservoir's sample.
void Renderer::Impl::TilePaths::restir_initial(const Impl& r) {
  const RenderSettings& s = ctx->s;
  r.restir_candidates(s, x0, y0, x1 - x0, y1 - y0, ctx->pass, ctx->use_tree, rsurf, rres, rngs);
  vis.clear();
  vis_pixel.clear();
  // A reservoir with W > 0 holds a sample whose target here (p_hat, the luminance of
  // restir_eval) is positive: only its shadow ray is needed.
  if (s.direct == DirectLighting::restir)
    for (size_t i = 0; i < count; ++i)
      if (rsurf[i].valid && rres[i].W > 0)
        vis.push_back(r.restir_shadow_ray(rsurf[i], rres[i].y)), vis_pixel.push_back(uint32_t(i));
}

void Renderer::Impl::TilePaths::restir_final(const Impl& r, std::span<const uint8_t> blocked) {
  const RenderSettings& s = ctx->s;
  for (size_t j = 0; j < vis.size(); ++j)
    if (blocked[j]) rres[vis_pixel[j]].W = 0;
  r.restir_reuse(*ctx->rp, s, x0, y0, x1 - x0, y1 - y0, rres, rsurf, rprev, rngs);
  for (size_t i = 0; i < count; ++i) {
    if (!rsurf[i].valid || !(rres[i].W > 0)) continue;
    Ray ray;
    const Vec3 c = r.restir_eval(rsurf[i], rres[i].y, &ray) * rres[i].W;
    if (luminance(c) > 0 && is_finite(c))
      shadow_rays.push_back(ray), shadows.push_back({c, uint32_t(i)});
  }
}

void Renderer::Impl::TilePaths::finish_bounce(std::span<const uint8_t> sun_blocked,
                                              std::span<const uint8_t> blocked) {
  // A path has at most one shadow ray per bounce: the order of the two lists changes no sum.
  for (size_t i = 0; i < sun_shadows.size(); ++i)
    if (!sun_blocked[i])
      paths[sun_shadows[i].path].radiance =
          paths[sun_shadows[i].path].radiance + sun_shadows[i].contribution;
  for (size_t i = 0; i < shadows.size(); ++i)
    if (!blocked[i])
      paths[shadows[i].path].radiance = paths[shadows[i].path].radiance + shadows[i].contribution;
  rays.swap(next_rays);
  active.swap(next_active);
}

void Renderer::Impl::TilePaths::end(Accumulator& acc) const {
  const RenderSettings& s = ctx->s;
  size_t i = 0;  // row by row: pixel i of the tile is image pixel p
  for (int y = y0; y < y1; ++y)
    for (size_t p = size_t(y) * size_t(s.width) + size_t(x0), e = p + size_t(x1 - x0); p < e;
         ++p, ++i) {
      acc.add(p, paths[i].radiance, px[i], s.clamp);
      Vec3 lc;
      if (paths[i].cache_key && cache_sample(paths[i], cache_vtx[i], s.clamp, lc))
        cache_records->push_back({paths[i].cache_key, lc});
    }
}

// ---- a wave of tiles -----------------------------------------------------------------------

// The tiles of a wave and the wave's batches, kept from wave to wave (no page faults frame
// after frame).
struct Renderer::Impl::Wave {
  std::vector<TilePaths> tiles;
  std::vector<size_t> offsets;  // tile i's rays of a batch: offsets[i] .. offsets[i + 1]
  std::vector<Ray> rays;
  std::vector<SurfaceHit> hits;
  std::vector<uint8_t> blocked;

  // One batch of the tiles' rays in tile order: member `which` of each tile, or with two
  // members, `first` of every tile, then `second` of every tile (tile i's rays of member m at
  // offsets[m n + i] .. offsets[m n + i + 1]).
  template <class Which>
  std::span<const Ray> gather(size_t n, Which which) {
    return gather(n, which, [](TilePaths&) -> const std::vector<Ray>* { return nullptr; });
  }
  template <class First, class Second>
  std::span<const Ray> gather(size_t n, First first, Second second) {
    const auto member = [&](size_t j) -> const std::vector<Ray>* {
      if (j < n) return &first(tiles[j]);
      return second(tiles[j - n]);
    };
    offsets.resize(2 * n + 1);
    offsets[0] = 0;
    for (size_t j = 0; j < 2 * n; ++j) {
      const std::vector<Ray>* r = member(j);
      offsets[j + 1] = offsets[j] + (r ? r->size() : 0);
    }
    rays.resize(offsets[2 * n]);
    parallel_for(0, 2 * n, 8, [&](size_t b, size_t e) {
      for (size_t j = b; j < e; ++j)
        if (const std::vector<Ray>* r = member(j))
          std::copy(r->begin(), r->end(), rays.begin() + std::ptrdiff_t(offsets[j]));
    });
    return rays;
  }
};

void Renderer::Impl::WaveDelete::operator()(Wave* w) const {
  delete w;
}

// One pass over a wave of tiles (the tiles `ids`, tile i's radiance cache records at
// records[i]): the tiles' paths advance a bounce at a time, each bounce's rays of every tile
// one batch for trace(), their shadow rays one for occluded() — batches large enough for the
// batch API's ray streams (traverse/stream.h) where it finds them faster.
void Renderer::Impl::render_wave(const WavePass& wp, std::span<const uint32_t> ids, int tiles_x,
                                 std::vector<CacheRecord>* records, Accumulator& acc,
                                 WaveStats& stats) {
  const double start = now_ms(), threads = double(current_thread_count());
  if (!wave) wave.reset(new Wave);
  Wave& wv = *wave;
  const size_t n = ids.size();
  if (wv.tiles.size() < n) wv.tiles.resize(n);
  auto timed = [&](auto&& fn, int kind, size_t rays) {
    const double t0 = now_ms();
    fn();
    stats.trace_ms += (now_ms() - t0) * threads;
    stats.rays[kind] += rays;
  };
  auto capture_batch = [&](int kind, std::span<const Ray> r) {
    if (!capture || r.empty()) return;
    std::vector<Ray>& dst = kind == 0   ? capture->camera
                            : kind == 1 ? capture->bounce
                                        : capture->shadow;
    dst.insert(dst.end(), r.begin(), r.end());
    (kind == 0   ? capture->camera_batches
     : kind == 1 ? capture->bounce_batches
                 : capture->shadow_batches)
        .push_back(r.size());
  };
  // Shadow rays (members `first` and `second` of each tile, as Wave::gather) traced as one
  // batch; each tile gets the results of its two lists.
  auto shadows = [&](auto first, auto second, auto&& then) {
    const std::span<const Ray> batch = wv.gather(n, first, second);
    wv.blocked.resize(batch.size());
    if (!batch.empty()) {
      capture_batch(2, batch);
      timed([&] { occluded(batch, wv.blocked); }, 2, batch.size());
    }
    const auto results = [&](size_t j) {
      return std::span<const uint8_t>(wv.blocked.data() + wv.offsets[j],
                                      wv.offsets[j + 1] - wv.offsets[j]);
    };
    parallel_for(0, n, 1, [&](size_t b, size_t e) {
      for (size_t i = b; i < e; ++i) then(wv.tiles[i], results(i), results(n + i));
    });
  };
  RenderStats::Steps& steps = stats.steps;
  double mark = start;
  const auto step = [&](double& into) {  // the wall time since the last step, into a step
    const double t = now_ms();
    into += t - mark;
    mark = t;
  };
  parallel_for(0, n, 1, [&](size_t b, size_t e) {
    for (size_t i = b; i < e; ++i)
      wv.tiles[i].begin(wp, int(ids[i] % uint32_t(tiles_x)), int(ids[i] / uint32_t(tiles_x)),
                        records ? &records[i] : nullptr);
  });
  step(steps.camera);
  for (int depth = 0;; ++depth) {
    const std::span<const Ray> batch =
        wv.gather(n, [](TilePaths& t) -> const std::vector<Ray>& { return t.rays; });
    if (batch.empty()) break;
    wv.hits.resize(batch.size());
    capture_batch(depth == 0 ? 0 : 1, batch);
    timed([&] { trace(batch, wv.hits); }, depth == 0 ? 0 : 1, batch.size());
    step(depth == 0 ? steps.trace_camera : steps.trace_bounces);
    parallel_for(0, n, 1, [&](size_t b, size_t e) {
      for (size_t i = b; i < e; ++i)
        wv.tiles[i].shade(*this, depth,
                          std::span<const SurfaceHit>(wv.hits.data() + wv.offsets[i],
                                                      wv.offsets[i + 1] - wv.offsets[i]));
    });
    step(depth == 0 ? steps.shade_first : steps.shade_bounces);
    if (wp.rp && depth == 0) {
      parallel_for(0, n, 1, [&](size_t b, size_t e) {
        for (size_t i = b; i < e; ++i) wv.tiles[i].restir_initial(*this);
      });
      shadows([](TilePaths& t) -> const std::vector<Ray>& { return t.vis; },
              [](TilePaths&) -> const std::vector<Ray>* { return nullptr; },
              [&](TilePaths& t, std::span<const uint8_t> blocked, std::span<const uint8_t>) {
                t.restir_final(*this, blocked);
              });
    }
    // The rays towards the sun of every tile first, so they meet as runs the batch API
    // traces as packets; then every tile's others.
    shadows([](TilePaths& t) -> const std::vector<Ray>& { return t.sun_rays; },
            [](TilePaths& t) -> const std::vector<Ray>* { return &t.shadow_rays; },
            [](TilePaths& t, std::span<const uint8_t> sun, std::span<const uint8_t> other) {
              t.finish_bounce(sun, other);
            });
    step(depth == 0 ? steps.shadows_first : steps.shadows_bounces);
  }
  parallel_for(0, n, 1, [&](size_t b, size_t e) {
    for (size_t i = b; i < e; ++i) wv.tiles[i].end(acc);
  });
  step(steps.film);
  stats.thread_ms += (now_ms() - start) * threads;
}

}  // namespace kestrel
