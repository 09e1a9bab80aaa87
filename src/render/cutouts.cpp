// Cut-out opacity (Material::AlphaMode): a hit on a masked or blended surface where that
// surface is not there is passed through — the ray is traced again from just past it — and a
// shadow ray is blocked only by a surface that is there. Scenes without such materials trace
// as before (one flag).
#include <cmath>
#include <cstring>
#include <vector>

#include "core/parallel.h"
#include "render/renderer_impl.h"

namespace kestrel {

using namespace render;

namespace {

// At most this many cut-out surfaces are passed along one ray; a ray that meets more stops at
// the last one it met (taken as there).
constexpr int max_cutout_layers = 64;

uint32_t bits_of(float f) {
  uint32_t b;
  std::memcpy(&b, &f, sizeof b);
  return b;
}

// A uniform number in [0, 1) fixed by the ray and the triangle: a blended surface lets a given
// ray through or not in every render, whatever the threads or the batches.
float blend_draw(const Ray& r, uint32_t instance, uint32_t prim) {
  uint64_t h = 0x9E3779B97F4A7C15ull;
  for (uint32_t w : {bits_of(r.org.x), bits_of(r.org.y), bits_of(r.org.z), bits_of(r.dir.x),
                     bits_of(r.dir.y), bits_of(r.dir.z), instance, prim}) {
    h = (h ^ w) * 0xFF51AFD7ED558CCDull;
    h ^= h >> 32;
  }
  return float(h >> 40) * 0x1p-24f;
}

// The few, scattered rays traced again: single rays, which keeps them out of the scene's
// timed choice of packets for the batches it is given (a camera batch's choice).
const TraceOptions single_rays{.isa = std::nullopt, .packets = false, .stream = false};

// Indices of the rays whose flag is set, in order.
std::vector<uint32_t> flagged(const std::vector<uint8_t>& flags) {
  std::vector<uint32_t> out;
  for (size_t i = 0; i < flags.size(); ++i)
    if (flags[i]) out.push_back(uint32_t(i));
  return out;
}

}  // namespace

bool Renderer::Impl::cut_out(const Ray& ray, const SurfaceHit& h) const {
  if (!h.hit() || h.instance_id >= instances.size() || !instances[h.instance_id].mesh) return false;
  const TriangleMesh& mesh = *instances[h.instance_id].mesh;
  const Material& m = material_of(mesh, h.prim_id);
  if (m.alpha_mode == Material::AlphaMode::opaque) return false;
  float alpha = m.alpha;
  if (const Texture* t = texture(m.alpha_texture))
    alpha *= sample_channel(*t, uv_at(mesh, h.prim_id, h.u, h.v), m.alpha_from_red ? 0 : 3);
  if (m.alpha_mode == Material::AlphaMode::mask) return !(alpha >= m.alpha_cutoff);
  return !(blend_draw(ray, h.instance_id, h.prim_id) < alpha);
}

void Renderer::Impl::trace(std::span<const Ray> rays, std::span<SurfaceHit> hits) const {
  scene->trace(rays, hits);
  if (cutouts) pass_cutouts(rays, hits);
}

void Renderer::Impl::pass_cutouts(std::span<const Ray> rays, std::span<SurfaceHit> hits) const {
  thread_local std::vector<uint8_t> flags_buffer;  // by reference, as occluded's
  std::vector<uint8_t>& flags = flags_buffer;
  flags.resize(rays.size());
  parallel_for(0, rays.size(), 4096, [&](size_t b, size_t e) {
    for (size_t i = b; i < e; ++i) flags[i] = cut_out(rays[i], hits[i]);
  });
  std::vector<uint32_t> pending = flagged(flags);
  std::vector<Ray> again;
  std::vector<SurfaceHit> again_hits;
  for (int layer = 0; layer < max_cutout_layers && !pending.empty(); ++layer) {
    // From just past the surface that is not there (a ray whose tmin passes its tmax misses).
    again.resize(pending.size());
    again_hits.assign(pending.size(), SurfaceHit{});
    for (size_t k = 0; k < pending.size(); ++k) {
      again[k] = rays[pending[k]];
      again[k].tmin = std::nextafter(hits[pending[k]].t, INFINITY);
    }
    scene->trace(again, again_hits, 0xFFFFFFFFu, single_rays);
    size_t n = 0;
    for (size_t k = 0; k < pending.size(); ++k) {
      hits[pending[k]] = again_hits[k];
      if (cut_out(again[k], again_hits[k])) pending[n++] = pending[k];
    }
    pending.resize(n);
  }
}

void Renderer::Impl::occluded(std::span<const Ray> rays, std::span<uint8_t> out) const {
  if (!cutouts) {
    scene->occluded(rays, out);
    return;
  }
  // The triangle an any-hit query found decides where it is opaque; where it is a cut-out,
  // the ray's closest surface that is there decides (the any hit may not be the closest).
  // Reused per calling thread (a fresh buffer of a batch's hits would be fresh pages every
  // call), by reference: a thread_local named inside the workers' lambda would be theirs.
  thread_local std::vector<SurfaceHit> any_buffer;
  thread_local std::vector<uint8_t> unsure_buffer;
  std::vector<SurfaceHit>& any = any_buffer;
  std::vector<uint8_t>& unsure = unsure_buffer;
  any.resize(rays.size());
  unsure.resize(rays.size());
  scene->any_hits(rays, any);
  parallel_for(0, rays.size(), 4096, [&](size_t b, size_t e) {
    for (size_t i = b; i < e; ++i) {
      const SurfaceHit& h = any[i];
      unsure[i] = h.hit() && material_of(*instances[h.instance_id].mesh, h.prim_id).alpha_mode !=
                                 Material::AlphaMode::opaque;
      out[i] = h.hit() && !unsure[i];
    }
  });
  const std::vector<uint32_t> check = flagged(unsure);
  if (check.empty()) return;
  std::vector<Ray> sub(check.size());
  std::vector<SurfaceHit> sub_hits(check.size());
  for (size_t k = 0; k < check.size(); ++k) sub[k] = rays[check[k]];
  scene->trace(sub, sub_hits, 0xFFFFFFFFu, single_rays);
  pass_cutouts(sub, sub_hits);
  for (size_t k = 0; k < check.size(); ++k) out[check[k]] = sub_hits[k].hit() ? 1 : 0;
}

}  // namespace kestrel
