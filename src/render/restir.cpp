// ReSTIR DI (Bitterli et al. 2020) at the first surface of each camera ray: resampled
// importance sampling of NEE's own strategies (the environment, the sun, the local lights by
// power or the light tree, presampled per 4 x 4 pixels) with the unshadowed contribution as
// the target, then temporal reuse (the history's reservoir at the pixel the motion vector
// points to, balance-heuristic weights over the two surfaces) and spatial reuse (neighbours
// of the same tile, so a tile depends on nothing another thread writes in this pass). Samples
// are shifted by identity (the same point on the same light, or the same direction), so no
// Jacobian enters. Spatial reuse normalises by 1/M (biased mode) or by the candidates of the
// reservoirs that could have produced the sample (unbiased mode, Alg. 6).
#include <algorithm>
#include <cmath>

#include "render/fast_math.h"
#include "render/renderer_impl.h"
#include "render/testing.h"

namespace kestrel {

using namespace render;

namespace {

constexpr float min_restir_alpha = 0.04f;  // roughness 0.2: sharper lobes keep NEE + MIS
constexpr float history_cap = 20;          // temporal M is capped at 20 x the new candidates
constexpr float spatial_radius = 16;       // pixels
constexpr int block = 4;                   // light presampling: one pool per 4 x 4 pixels
constexpr int max_candidates = 64;         // RenderSettings::restir_candidates at most

bool similar(const RestirSurface& a, const RestirSurface& b) {
  return b.valid && dot(a.n, b.n) > 0.9f && std::fabs(a.depth - b.depth) <= 0.1f * a.depth;
}

// Streams reservoir r, whose target at the surface being shaded is p_hat, into out.
bool stream(Reservoir& out, const Reservoir& r, float p_hat, Rng& rng) {
  const float w = p_hat * r.W * r.M;
  out.M += r.M;
  const float u = rng.uniform();
  if (!(w > 0) || !std::isfinite(w)) return false;
  out.w_sum += w;
  if (u * out.w_sum >= w) return false;
  out.y = r.y, out.p_hat = p_hat;
  return true;
}

}  // namespace

bool Renderer::Impl::restir_eligible(const Surface& sf) const {
  return sf.bp.alpha >= min_restir_alpha && !(sf.bp.transmission > 0) &&
         (p_env > 0 || p_sun > 0 || local_light_count() > 0);
}

// What y sends towards the surface: its direction wi (and dir, the shadow ray's direction
// over its length tmax), radiance le and geometry term G; false where y gives nothing there
// (an emitter's point at the origin, a punctual light out of range, no light) — with no
// other branch on the sample, so that restir_target can combine the tests.
[[gnu::always_inline]] inline bool Renderer::Impl::restir_light(Vec3 origin, const LightRef& y,
                                                                Vec3& wi, Vec3& dir, Vec3& le,
                                                                float& geometry,
                                                                float& tmax) const {
  geometry = 1, tmax = INFINITY;
  if (y.id == LightRef::env) {
    wi = dir = y.v;
    le = env_radiance(wi);
    return true;
  }
  if (y.id == LightRef::sun) {
    wi = dir = y.v;
    le = sun_on ? sun_radiance : Vec3{0, 0, 0};
    return true;
  }
  if (y.id < lights.size()) {
    const LightTri& l = lights[y.id];
    const Vec3 q = l.p0 + l.e1 * y.v.x + l.e2 * y.v.y;
    dir = q - origin;
    const float dist2 = dot(dir, dir);
    wi = dir * (1.0f / std::sqrt(dist2));
    le = light_emission(l, y.v.x, y.v.y);
    geometry = std::fabs(dot(l.normal, wi)) / dist2;
    tmax = 1.0f - 1e-3f;
    return dist2 > 0;
  }
  if (y.id < local_light_count())
    return punctual_light(punctual[y.id - lights.size()], origin, wi, dir, le, tmax);
  return false;
}

Vec3 Renderer::Impl::restir_eval(const RestirShading& s, const LightRef& y, Ray* shadow) const {
  Vec3 wi, dir, le;
  float geometry, tmax;
  if (!restir_light(s.origin, y, wi, dir, le, geometry, tmax)) return {0, 0, 0};
  if (!(dot(wi, s.g.ng) > 0) || !(luminance(le) > 0) || !(geometry > 0)) return {0, 0, 0};
  Vec3 f;
  s.bsdf.eval(s.frame.to_local(wi), f, nullptr);
  if (shadow) *shadow = Ray{s.origin, dir, 0.0f, tmax};
  return f * le * geometry;
}

Ray Renderer::Impl::restir_shadow_ray(const RestirSurface& g, const LightRef& y) const {
  const Vec3 origin = offset_origin(g.p, g.ng);
  Vec3 wi, dir, le;
  float geometry, tmax;
  restir_light(origin, y, wi, dir, le, geometry, tmax);
  return Ray{origin, dir, 0.0f, tmax};
}

// restir_eval's luminance with its tests on the sample (towards the surface's side, lit, a
// positive geometry term) combined instead of taken one by one: a batch of candidates, about
// half of which face away at random, evaluates without a misprediction each.
float Renderer::Impl::restir_target(const RestirShading& s, const LightRef& y) const {
  Vec3 wi{0, 0, 1}, dir, le{0, 0, 0};
  float geometry, tmax;
  const bool ok = restir_light(s.origin, y, wi, dir, le, geometry, tmax) & (dot(wi, s.g.ng) > 0) &
                  (luminance(le) > 0) & (geometry > 0);
  Vec3 f;
  s.bsdf.eval(s.frame.to_local(wi), f, nullptr);
  const float p = luminance(f * le * geometry);
  return ok ? p : 0.0f;
}

Renderer::Impl::LightDraw Renderer::Impl::local_light_sample(Vec3 origin, bool tree, float u,
                                                             float u1, float u2) const {
  u = std::min(local_light_count() == 1 ? 0.5f : u, 0x1.fffffep-1f);
  float pick = 0;
  size_t li = 0;
  if (tree) {
    li = light_tree.sample(origin, u, pick);
  } else {
    li = light_dist.sample(u);
    pick = light_dist.pmf(li);
  }
  return local_light_draw(li, pick, u1, u2);
}

void Renderer::Impl::local_light_samples(Vec3 origin, bool tree, const float* u, const float* u1,
                                         const float* u2, size_t n, LightDraw* out) const {
  if (!tree) {
    for (size_t i = 0; i < n; ++i) out[i] = local_light_sample(origin, false, u[i], u1[i], u2[i]);
    return;
  }
  constexpr size_t chunk = 16;
  float uc[chunk], pick[chunk];
  uint32_t li[chunk];
  for (size_t i0 = 0; i0 < n; i0 += chunk) {
    const size_t m = std::min(chunk, n - i0);
    for (size_t j = 0; j < m; ++j)
      uc[j] = std::min(local_light_count() == 1 ? 0.5f : u[i0 + j], 0x1.fffffep-1f);
    light_tree.sample(origin, uc, m, li, pick);
    for (size_t j = 0; j < m; ++j)
      out[i0 + j] = local_light_draw(li[j], pick[j], u1[i0 + j], u2[i0 + j]);
  }
}

Renderer::Impl::LightDraw Renderer::Impl::local_light_draw(size_t li, float pick, float u1,
                                                           float u2) const {
  LightDraw e{{uint32_t(li), {0, 0, 0}}, (1 - p_env - p_sun) * pick};
  if (li < lights.size()) {  // uniform on the triangle: an area density
    const float su = std::sqrt(u1);
    e.y.v = {u2 * su, 1 - su, 0};
    e.pdf /= lights[li].area;
  }
  return e;
}

void Renderer::Impl::restir_candidates(const RenderSettings& s, int x0, int y0, int w, int h,
                                       int pass, bool tree, std::span<const RestirSurface> surf,
                                       std::span<Reservoir> res, std::span<Rng> rngs) const {
  using Entry = LightDraw;
  Entry pool[block * block];
  // A pixel's candidates (their resampling uniforms), and the walks of those drawn at its own
  // surface: kept across pixels (not filled per pixel).
  const int m = std::clamp(s.restir_candidates, 1, max_candidates);
  Entry cand[max_candidates], drawn[max_candidates];
  float us[max_candidates], ou[max_candidates], ou1[max_candidates], ou2[max_candidates];
  int own_of[max_candidates];
  for (int by = 0; by < h; by += block)
    for (int bx = 0; bx < w; bx += block) {
      const int bw = std::min(block, w - bx), bh = std::min(block, h - by);
      // The block's surface: its centre pixel's, else the first valid one.
      const RestirSurface* g = nullptr;
      const size_t centre = size_t(by + bh / 2) * size_t(w) + size_t(bx + bw / 2);
      if (surf[centre].valid) g = &surf[centre];
      for (int y = by; y < by + bh && !g; ++y)
        for (int x = bx; x < bx + bw && !g; ++x)
          if (surf[size_t(y) * size_t(w) + size_t(x)].valid)
            g = &surf[size_t(y) * size_t(w) + size_t(x)];
      if (!g) continue;
      const uint64_t block_id = uint64_t(y0 + by) * uint64_t(s.width) + uint64_t(x0 + bx);
      Rng rng(s.seed ^ 0x5E57125EEDull, s.frame, block_id, uint64_t(pass));
      // The pool holds local lights only: the environment and the sun are sampled per pixel
      // (cheap, and the environment's strategy depends on the pixel's normal).
      const Vec3 origin = offset_origin(g->p, g->ng);
      const int n = local_light_count() > 0 ? block * block : 0;
      float pu[block * block], pu1[block * block], pu2[block * block];
      for (int c = 0; c < n; ++c)
        pu[c] = rng.uniform(), pu1[c] = rng.uniform(), pu2[c] = rng.uniform();
      local_light_samples(origin, tree, pu, pu1, pu2, size_t(n), pool);
      // Each pixel: M candidates of NEE's mixture, a local light being one drawn uniformly
      // from the pool (each entry is distributed as the pool's strategy, which is all RIS
      // needs), resampled by the target at its surface. A pixel whose surface is not like
      // the block's (across a depth edge) samples its own lights: the pool's probabilities
      // there could be near zero for the lights that matter, fireflies that reuse spreads.
      for (int y = by; y < by + bh; ++y)
        for (int x = bx; x < bx + bw; ++x) {
          const size_t i = size_t(y) * size_t(w) + size_t(x);
          if (!surf[i].valid) continue;
          const bool own = tree && !similar(surf[i], *g);  // power: the same everywhere
          const RestirShading at(surf[i]);
          Reservoir r;
          Rng& pr = rngs[i];
          // The candidates, then their own lights' walks together, then resampling.
          int owns = 0;
          for (int c = 0; c < m; ++c) {
            const float ul = pr.uniform(), u1 = pr.uniform(), u2 = pr.uniform();
            us[c] = pr.uniform();
            Entry& e = cand[c];
            e = Entry{{}, 0};
            if (ul < p_env) {
              float epdf = 0;
              e.y = {LightRef::env, env_sample(u1, u2, surf[i].n, epdf)};
              e.pdf = p_env * epdf;
            } else if (ul < p_env + p_sun) {
              e.y = {LightRef::sun, sun_sample(u1, u2)};
              e.pdf = p_sun / sun_solid_angle;
            } else if (own && n > 0) {
              ou[owns] = (ul - p_env - p_sun) / (1 - p_env - p_sun), ou1[owns] = u1, ou2[owns] = u2;
              own_of[owns++] = c;
            } else if (n > 0) {
              e = pool[std::min(int(u1 * float(n)), n - 1)];
            }
          }
          if (owns > 0) {
            local_light_samples(at.origin, tree, ou, ou1, ou2, size_t(owns), drawn);
            for (int j = 0; j < owns; ++j) cand[own_of[j]] = drawn[j];
          }
          // Resampling without a branch per candidate: a candidate that adds nothing (a
          // weight that is not positive and finite) adds 0 and is never taken.
          int taken = -1;
          for (int c = 0; c < m; ++c) {
            const Entry& e = cand[c];
            r.M += 1;
            if (!(e.pdf > 0) || !std::isfinite(e.pdf)) continue;
            const float p_hat = restir_target(at, e.y);
            const float wgt = p_hat / e.pdf;
            const bool adds = (wgt > 0) & (wgt < INFINITY);
            r.w_sum += adds ? wgt : 0.0f;
            const bool take = adds & (us[c] * r.w_sum < wgt);
            taken = take ? c : taken;
            r.p_hat = take ? p_hat : r.p_hat;
          }
          if (taken >= 0) r.y = cand[taken].y;
          r.W = r.p_hat > 0 ? r.w_sum / (r.M * r.p_hat) : 0.0f;
          res[i] = r;
        }
    }
}

void Renderer::Impl::restir_reuse(const RestirPass& rp, const RenderSettings& s, int x0, int y0,
                                  int w, int h, std::span<Reservoir> res,
                                  std::span<const RestirSurface> surf,
                                  std::span<const int32_t> prev_pixel, std::span<Rng> rngs) const {
  const bool unbiased = s.direct == DirectLighting::restir_unbiased;
  const size_t count = size_t(w) * size_t(h);
  // The reservoirs combined at x: each with the surface its target belongs to.
  struct Source {
    Reservoir r;
    const RestirSurface* at;
  };
  Source in[1 + 16];
  // Combines in[0..n) at x (in[0] is x's own); W normalised by 1/M or by Alg. 6's Z.
  auto combine = [&](const RestirSurface& x, int n, Rng& rng) {
    Reservoir out;
    int chosen = -1;
    const RestirShading xs(x);
    for (int j = 0; j < n; ++j) {
      const Reservoir& r = in[j].r;
      const float p_hat = j == 0 ? r.p_hat : restir_target(xs, r.y);
      if (stream(out, r, p_hat, rng)) chosen = j;
    }
    if (chosen < 0 || !(out.p_hat > 0)) return Reservoir{{}, 0, out.M, 0, 0};
    float z = out.M;
    if (unbiased) {
      z = 0;
      for (int j = 0; j < n; ++j)
        if (j == chosen || luminance(restir_eval(*in[j].at, out.y, nullptr)) > 0) z += in[j].r.M;
    }
    out.W = out.w_sum / (z * out.p_hat);
    return out;
  };
  // Temporal reuse.
  std::vector<Reservoir> temporal(res.begin(), res.end());
  if (rp.prev)
    for (size_t i = 0; i < count; ++i) {
      const RestirSurface& x = surf[i];
      if (!x.valid || prev_pixel[i] < 0) continue;
      const size_t q = size_t(prev_pixel[i]);
      if (q >= rp.prev->res.size() || !similar(x, rp.prev->surf[q])) continue;
      // Two reservoirs, the new (c, at x) and the history (h, at its own surface), weighted
      // by the balance heuristic over where each came from: m_c(y) = M_c p_x(y) / (M_c p_x(y)
      // + M_h p_h(y)), and m_h likewise. Unbiased, and a sample that is bright here but was
      // dim where it was found is not over-weighted (1/M weights would make it a firefly).
      const RestirSurface& hs = rp.prev->surf[q];
      const Reservoir& c = res[i];
      Reservoir h = rp.prev->res[q];
      h.M = std::min(h.M, history_cap * std::max(1.0f, c.M));
      const float pc_x = c.p_hat, pc_h = c.W > 0 ? restir_target(RestirShading(hs), c.y) : 0;
      const float ph_h = h.p_hat, ph_x = h.W > 0 ? restir_target(RestirShading(x), h.y) : 0;
      auto mis = [](float m_a, float p_a, float m_b, float p_b) {
        const float d = m_a * p_a + m_b * p_b;
        return d > 0 ? m_a * p_a / d : 0.0f;
      };
      Reservoir out;
      out.M = c.M + h.M;
      const float wc = mis(c.M, pc_x, h.M, pc_h) * pc_x * c.W;
      const float wh = mis(h.M, ph_h, c.M, ph_x) * ph_x * h.W;
      Rng& rng = rngs[i];
      const float u = rng.uniform();
      if (wc > 0 && std::isfinite(wc)) out.w_sum += wc, out.y = c.y, out.p_hat = pc_x;
      if (wh > 0 && std::isfinite(wh)) {
        out.w_sum += wh;
        if (u * out.w_sum < wh) out.y = h.y, out.p_hat = ph_x;
      }
      out.W = out.p_hat > 0 && out.w_sum > 0 ? out.w_sum / out.p_hat : 0.0f;
      temporal[i] = out;
    }
  // Spatial reuse: neighbours in a disk, inside the tile, on a similar surface.
  const int k = std::clamp(s.restir_neighbors, 0, 16);
  for (size_t i = 0; i < count; ++i) {
    const RestirSurface& x = surf[i];
    if (!x.valid) continue;
    Rng& rng = rngs[i];
    const int px = int(i % size_t(w)), py = int(i / size_t(w));
    in[0] = {temporal[i], &x};
    int n = 1;
    for (int j = 0; j < k; ++j) {
      // A point of the disk (uniform in area), rounded to the nearest pixel offset.
      const float r = spatial_radius * std::sqrt(rng.uniform());
      float sin_phi, cos_phi;  // of phi = 2 pi u
      sincos_2pi(rng.uniform(), sin_phi, cos_phi);
      const int nx = px + int(round_even(r * cos_phi)), ny = py + int(round_even(r * sin_phi));
      if (nx < 0 || ny < 0 || nx >= w || ny >= h || (nx == px && ny == py)) continue;
      const size_t q = size_t(ny) * size_t(w) + size_t(nx);
      if (!similar(x, surf[q])) continue;
      in[n++] = {temporal[q], &surf[q]};
    }
    res[i] = n > 1 ? combine(x, n, rng) : temporal[i];
  }
  for (size_t i = 0; i < count; ++i) {
    const size_t g = size_t(y0 + int(i / size_t(w))) * size_t(s.width) + size_t(x0) + i % size_t(w);
    rp.cur->res[g] = res[i];
    rp.cur->surf[g] = surf[i];
  }
}

std::array<size_t, 2> RendererTesting::restir_target_check(const Renderer& renderer, int n,
                                                           uint64_t seed) {
  const Renderer::Impl& r = *renderer.impl_;
  Rng rng(seed, 0, 0, 0);
  const auto unit = [&] {
    const float z = 2 * rng.uniform() - 1, a = 2 * pi * rng.uniform(),
                s = std::sqrt(std::max(0.0f, 1 - z * z));
    return Vec3{s * std::cos(a), s * std::sin(a), z};
  };
  const Vec3 lo = r.bounds.lo, span = r.bounds.hi - r.bounds.lo;
  std::array<size_t, 2> out{0, 0};
  for (int i = 0; i < n; ++i) {
    RestirSurface g;
    g.p = lo + Vec3{span.x * rng.uniform(), span.y * rng.uniform(), span.z * rng.uniform()};
    g.ng = unit();
    g.n = normalize(g.ng + unit() * 0.7f);
    g.wo_l = normalize(unit() + Vec3{0, 0, 0.8f});
    g.bp.base = {rng.uniform(), rng.uniform(), rng.uniform()};
    g.bp.metallic = rng.uniform() < 0.3f ? 1.0f : rng.uniform() < 0.5f ? 0.0f : rng.uniform();
    g.bp.alpha = std::max(rng.uniform() * rng.uniform(), min_alpha);
    g.bp.specular = rng.uniform() < 0.3f ? 0.0f : rng.uniform();
    g.depth = 1, g.valid = true;
    LightRef y;
    const float kind = rng.uniform();
    if (kind < 0.15f) {
      y = {LightRef::env, unit()};
    } else if (kind < 0.3f) {
      y = {LightRef::sun, unit()};
    } else if (r.local_light_count() > 0) {
      y.id = std::min(uint32_t(rng.uniform() * float(r.local_light_count())),
                      uint32_t(r.local_light_count() - 1));
      const float su = std::sqrt(rng.uniform());
      y.v = {rng.uniform() * su, 1 - su, 0};
    }
    const RestirShading s(g);
    const float target = r.restir_target(s, y), full = luminance(r.restir_eval(s, y, nullptr));
    if (!(target == full || (std::isnan(target) && std::isnan(full)))) ++out[0];
    if (target > 0) ++out[1];
  }
  return out;
}

}  // namespace kestrel
