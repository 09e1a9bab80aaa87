// The surface at a hit, as the path tracer's shading reads it: prefetching what it reads
// ahead of the shading loop (indices, vertices, texels), the hit's geometry, its material's
// roughness and its full BSDF parameters; the radiance cache's early answer at a hit.
#include <algorithm>
#include <cmath>

#include "render/bsdf.h"
#include "render/renderer_impl.h"
#include "render/surface_rows.h"

namespace kestrel {

using namespace render;

// ---- prefetching what shading a hit reads ----------------------------------------------------

void Renderer::Impl::prefetch_indices(const SurfaceHit& h) const {
  if (!h.hit()) return;
  const TriangleMesh& m = *instances[h.instance_id].mesh;
  __builtin_prefetch(&m.indices[3 * size_t(h.prim_id)]);
  if (!m.material_ids.empty()) __builtin_prefetch(&m.material_ids[h.prim_id]);
}
void Renderer::Impl::prefetch_vertices(const SurfaceHit& h) const {
  if (!h.hit()) return;
  const TriangleMesh& m = *instances[h.instance_id].mesh;
  for (int c = 0; c < 3; ++c) {
    const uint32_t i = m.indices[3 * size_t(h.prim_id) + size_t(c)];
    __builtin_prefetch(&m.positions[i]);
    if (!m.normals.empty()) __builtin_prefetch(&m.normals[i]);
    if (!m.uvs.empty()) __builtin_prefetch(&m.uvs[i]);
  }
}
// The base colour texels, once the uvs are near.
void Renderer::Impl::prefetch_texels(const SurfaceHit& h) const {
  if (!h.hit()) return;
  const TriangleMesh& m = *instances[h.instance_id].mesh;
  if (m.uvs.empty()) return;
  prefetch_texels(h, uv_at(m, h.prim_id, h.u, h.v));
}
// The same where the hit's texture coordinates are known.
void Renderer::Impl::prefetch_texels(const SurfaceHit& h, Vec2 uv) const {
  const TriangleMesh& m = *instances[h.instance_id].mesh;
  const Texture* t = maps_of(material_of(m, h.prim_id)).base;
  if (!t) return;
  const float u = uv.x, v = uv.y;
  const float x = (u - floor_exact(u)) * float(t->width),
              y = (v - floor_exact(v)) * float(t->height);
  if (!(x >= 0 && x < float(t->width) && y >= 0 && y < float(t->height))) return;
  const size_t row = size_t(y) * size_t(t->width);
  __builtin_prefetch(&t->rgba[(row + size_t(x)) * 4]);
  if (size_t(y) + 1 < size_t(t->height))
    __builtin_prefetch(&t->rgba[(row + size_t(t->width) + size_t(x)) * 4]);
}

// ---- the surface at a hit --------------------------------------------------------------------

// surface_at's first part: the world position (and the object-space one, for motion
// vectors), the geometric normal facing the ray, the material.
void Renderer::Impl::surface_geometry(const SurfaceHit& h, const Ray& ray, Surface& sf) const {
  const InstanceShade& is = instances[h.instance_id];
  const TriangleMesh& mesh = *is.mesh;
  const uint32_t i0 = mesh.indices[3 * h.prim_id], i1 = mesh.indices[3 * h.prim_id + 1],
                 i2 = mesh.indices[3 * h.prim_id + 2];
  const float b0 = 1 - h.u - h.v;
  Vec3 p0 = mesh.positions[i0], p1 = mesh.positions[i1], p2 = mesh.positions[i2];
  sf.p_obj = p0 * b0 + p1 * h.u + p2 * h.v;
  if (is.identity) {
    sf.p = sf.p_obj;
  } else {
    p0 = is.xf.point(p0), p1 = is.xf.point(p1), p2 = is.xf.point(p2);
    sf.p = p0 * b0 + p1 * h.u + p2 * h.v;
  }
  const Vec3 wo = sf.wo = -ray.dir;
  Vec3 ng = cross(p1 - p0, p2 - p0);
  const float ng_len = length(ng);
  ng = ng_len > 0 ? ng * (1.0f / ng_len) : -wo;
  sf.cos_hit = dot(ng, wo);
  sf.ng = sf.cos_hit < 0 ? -ng : ng;
  sf.mat = &material_of(mesh, h.prim_id);
}

// World position (and object-space position, for motion vectors), geometric and shading
// normals facing the ray, texture coordinates, and the material's BSDF parameters there.
Renderer::Impl::Surface Renderer::Impl::surface_at(const SurfaceHit& h, const Ray& ray) const {
  Surface sf;
  surface_geometry(h, ray, sf);
  const InstanceShade& is = instances[h.instance_id];
  const TriangleMesh& mesh = *is.mesh;
  const float b0 = 1 - h.u - h.v;
  const Vec3 ng = sf.ng, wo = sf.wo;
  Vec3 ns = ng;
  if (!mesh.normals.empty()) {
    const uint32_t i0 = mesh.indices[3 * h.prim_id], i1 = mesh.indices[3 * h.prim_id + 1],
                   i2 = mesh.indices[3 * h.prim_id + 2];
    Vec3 nn = mesh.normals[i0] * b0 + mesh.normals[i1] * h.u + mesh.normals[i2] * h.v;
    if (!is.identity) nn = normal_transform(is.nrm, nn);
    const float len = length(nn);
    if (len > 0 && std::isfinite(len)) {
      nn = nn * (1.0f / len);
      if (dot(nn, ng) < 0) nn = -nn;
      if (dot(nn, wo) > 1e-4f) ns = nn;
    }
  }
  sf.uv = uv_at(mesh, h.prim_id, h.u, h.v);
  sf.ns = ns;
  normal_map(h, sf);
  surface_material(sf);
  if (is.colors) vertex_colors(h, sf);
  return sf;
}

// A material's normal map (glTF: tangent space, +X along u, +Y against v, linear texels) tilts
// the shading normal. The tangent frame comes from the triangle's texture coordinates: T =
// dp/du made orthogonal to ns, B = ns x T turned to point against dp/dv (mirrored mappings
// keep their handedness); a back face mirrors T and B with the normal, as glTF's sample
// viewer does. A tilted normal that would face away from the viewer is not used.
void Renderer::Impl::normal_map(const SurfaceHit& h, Surface& sf) const {
  const Material& mat = *sf.mat;
  const Texture* t = texture(mat.normal_texture);
  if (!t) return;
  const InstanceShade& is = instances[h.instance_id];
  const TriangleMesh& mesh = *is.mesh;
  if (mesh.uvs.empty()) return;
  const uint32_t* idx = &mesh.indices[3 * size_t(h.prim_id)];
  Vec3 p0 = mesh.positions[idx[0]], p1 = mesh.positions[idx[1]], p2 = mesh.positions[idx[2]];
  if (!is.identity) p0 = is.xf.point(p0), p1 = is.xf.point(p1), p2 = is.xf.point(p2);
  const Vec2 t0 = mesh.uvs[idx[0]], t1 = mesh.uvs[idx[1]], t2 = mesh.uvs[idx[2]];
  const Vec3 e1 = p1 - p0, e2 = p2 - p0;
  const float du1 = t1.x - t0.x, dv1 = t1.y - t0.y, du2 = t2.x - t0.x, dv2 = t2.y - t0.y;
  const float det = du1 * dv2 - du2 * dv1;
  if (!(std::fabs(det) > 0) || !std::isfinite(det)) return;  // no mapping to follow
  const float r = 1.0f / det;
  const Vec3 dpdu = (e1 * dv2 - e2 * dv1) * r, dpdv = (e2 * du1 - e1 * du2) * r;
  const Vec3 ns = sf.ns;
  Vec3 tangent = dpdu - ns * dot(ns, dpdu);
  const float len = length(tangent);
  if (!(len > 0) || !std::isfinite(len)) return;
  tangent = tangent * (1.0f / len);
  Vec3 bitangent = cross(ns, tangent);
  if (dot(bitangent, dpdv) > 0) bitangent = -bitangent;
  if (sf.cos_hit < 0) tangent = -tangent, bitangent = -bitangent;
  const float x = (sample_channel(*t, sf.uv, 0) * 2 - 1) * mat.normal_scale,
              y = (sample_channel(*t, sf.uv, 1) * 2 - 1) * mat.normal_scale,
              z = sample_channel(*t, sf.uv, 2) * 2 - 1;
  Vec3 n = tangent * x + bitangent * y + ns * z;
  const float n_len = length(n);
  if (!(n_len > 0) || !std::isfinite(n_len)) return;
  n = n * (1.0f / n_len);
  if (dot(n, sf.wo) > 1e-4f) sf.ns = n;
}

// surface_at from a hit's entry j of SIMD rows (the same values).
Renderer::Impl::Surface Renderer::Impl::surface_from_rows(const SurfaceRows& rows, int j,
                                                          const SurfaceHit& h,
                                                          const Ray& ray) const {
  Surface sf;
  sf.p = {rows.px[j], rows.py[j], rows.pz[j]};
  sf.p_obj = {rows.ox[j], rows.oy[j], rows.oz[j]};
  sf.wo = -ray.dir;
  sf.ng = {rows.gx[j], rows.gy[j], rows.gz[j]};
  sf.cos_hit = rows.cos_hit[j];
  const InstanceShade& is = instances[h.instance_id];
  sf.mat = &material_of(*is.mesh, h.prim_id);
  sf.ns = {rows.nx[j], rows.ny[j], rows.nz[j]};
  sf.uv = {rows.u[j], rows.v[j]};
  normal_map(h, sf);
  const float texel[3] = {rows.tr[j], rows.tg[j], rows.tb[j]};
  surface_material(sf, (rows.texel >> j) & 1u ? texel : nullptr);
  if (is.colors) vertex_colors(h, sf);
  return sf;
}

void Renderer::Impl::vertex_colors(const SurfaceHit& h, Surface& sf) const {
  const TriangleMesh& m = *instances[h.instance_id].mesh;  // (InstanceShade::colors: it has them)
  const uint32_t* idx = &m.indices[3 * size_t(h.prim_id)];
  const Vec3 c =
      m.colors[idx[0]] * (1 - h.u - h.v) + m.colors[idx[1]] * h.u + m.colors[idx[2]] * h.v;
  sf.bp.base = min(max(sf.bp.base * c, Vec3{0, 0, 0}), Vec3{1, 1, 1});
}

// surface_at's last part: the material's BSDF parameters at sf.uv (`texel`: its base
// colour's texel there, when known).
void Renderer::Impl::surface_material(Surface& sf, const float* texel) const {
  const Vec2 uv = sf.uv;
  const Material& mat = *sf.mat;
  BsdfParams& bp = sf.bp;
  bp.base = mat.base_color;
  if (const Texture* t = maps_of(mat).base) {
    float c[3];
    if (texel)
      c[0] = texel[0], c[1] = texel[1], c[2] = texel[2];
    else
      sample_texture(*t, uv, true, c);
    bp.base = bp.base * Vec3{c[0], c[1], c[2]};
  }
  bp.base = min(max(bp.base, Vec3{0, 0, 0}), Vec3{1, 1, 1});
  const float roughness = roughness_at(
      mat, [uv] { return uv; }, bp.metallic);
  bp.alpha = std::max(roughness * roughness, min_alpha);
  bp.specular = std::clamp(mat.specular, 0.0f, 1.0f);
  bp.f0 = maps_of(mat).f0;
  bp.transmission = mat.transmission;  // in [0, 1] (check_materials)
  if (bp.transmission > 0) {
    // Glass: a solid's faces bend light (eta by the side the ray is on: the front face is the
    // outside); an IOR of ~1 bends none, the same as a sheet. (ior >= 1: check_materials.)
    const float ior = mat.ior;
    bp.thin = mat.thin_walled || ior < 1.001f;
    bp.eta = bp.thin || sf.cos_hit >= 0 ? ior : 1.0f / ior;
  }
  sf.roughness = roughness;
}

// The rows of a group of hits (at most SurfaceRows::size): the lanes on the first hit's
// instance (bit j of the result: entry j is hit j's).
uint32_t Renderer::Impl::surface_rows_of(const SurfaceRowsKernels& kernels, const SurfaceHit* hits,
                                         const Ray* rays, size_t n, bool texels,
                                         SurfaceRows& rows) const {
  size_t first = 0;
  while (first < n && !hits[first].hit()) ++first;
  if (first == n) return 0;
  const uint32_t id = hits[first].instance_id;
  const InstanceShade& is = instances[id];
  const TriangleMesh& m = *is.mesh;
  // The lanes gather at 32-bit float offsets: 3 per vertex and per triangle.
  if (m.positions.size() >= (size_t(1) << 29) || m.indices.size() >= (size_t(1) << 31)) return 0;
  SurfaceRowsArgs a;
  a.indices = m.indices.data(), a.positions = m.positions.data();
  a.normals = m.normals.empty() ? nullptr : m.normals.data();
  a.uvs = m.uvs.empty() ? nullptr : m.uvs.data();
  a.hits = hits, a.rays = rays, a.n = n, a.instance = id, a.out = &rows;
  if (!is.identity) a.xf = is.xf.m, a.nrm = is.nrm;
  kernels.surfaces(a);
  uint32_t mask = 0;
  for (size_t j = first; j < n; ++j) mask |= uint32_t(hits[j].instance_id == id) << j;
  // The base texels of the lanes whose material has the first such lane's texture.
  rows.texel = 0;
  if (!texels) return mask;
  const Texture* texture = nullptr;
  for (size_t j = first; j < n; ++j) {
    if (!((mask >> j) & 1u)) continue;
    const Texture* t = maps_of(material_of(m, hits[j].prim_id)).base;
    if (t && !texture) texture = t;
    if (t && t == texture) rows.texel |= 1u << j;
  }
  const size_t size = texture ? size_t(texture->width) * size_t(texture->height) : 0;
  if (texture && texture->width > 0 && texture->height > 0 && size < (size_t(1) << 31) &&
      texture->rgba.size() >= 4 * size) {
    TexelRowsArgs ta;
    ta.rgba = texture->rgba.data(), ta.width = texture->width, ta.height = texture->height;
    ta.srgb = srgb_decode_table(), ta.n = n, ta.rows = &rows;
    kernels.texels(ta);
  } else {
    rows.texel = 0;
  }
  return mask;
}

Renderer::Impl::SurfaceGroups::SurfaceGroups(const Impl& r, const SurfaceRowsKernels* kernels,
                                             std::span<const SurfaceHit> hits, const Ray* rays,
                                             bool texels, const Rng* rngs, const uint32_t* active)
    : r_(r),
      hits_(hits),
      rays_(rays),
      texels_(texels),
      kernels_(kernels),
      rngs_(rngs),
      active_(active),
      sun_basis_{r.sun_frame.t, r.sun_frame.b, r.sun_frame.n} {
  make(0);
  make(1);
}

void Renderer::Impl::SurfaceGroups::make(size_t g) {
  const size_t b = g * group, n = hits_.size();
  in_rows_[g & 1] = kernels_ && b < n
                        ? r_.surface_rows_of(*kernels_, &hits_[b], &rays_[b],
                                             std::min(group, n - b), texels_, rows_[g & 1])
                        : 0;
  // The group's paths' next draws (PathDraws: the light sample's and the BSDF sample's), not
  // for a group of misses (the sky around an object).
  drawn_[g & 1] = false;
  if (!kernels_ || !rngs_ || b >= n) return;
  const size_t m = std::min(group, n - b);
  bool any = false;
  for (size_t j = 0; j < m; ++j) any |= hits_[b + j].hit();
  if (!any) return;
  drawn_[g & 1] = true;
  uint64_t state[group], inc[group];
  for (size_t j = 0; j < m; ++j) {
    const Rng& rng = rngs_[active_[b + j]];
    state[j] = rng.state(), inc[j] = rng.increment();
  }
  PathDrawsArgs a;
  a.state = state, a.inc = inc, a.n = m, a.out = &draws_[g & 1];
  if (r_.p_sun > 0) a.sun_frame = sun_basis_, a.sun_cos_max = r_.sun_cos_max;
  kernels_->draws(a);
}

RadianceCache::Cell Renderer::Impl::cache_cell(const SurfaceRows& rows, int j) const {
  const RadianceCache::Cell cell = radiance_cache.cell({rows.px[j], rows.py[j], rows.pz[j]},
                                                       {rows.gx[j], rows.gy[j], rows.gz[j]});
  radiance_cache.prefetch(cell.key);
  return cell;
}

const SurfaceRowsKernels& render::surface_rows_kernels(Isa isa) {
  require_supported(isa);
  switch (isa) {
    case Isa::avx512:
      return surface_rows_avx512();
    case Isa::avx2:
      return surface_rows_avx2();
    default:
      return surface_rows_sse2();
  }
}

// ---- the radiance cache's early answer ------------------------------------------------------

// The radiance cache's answer at a path's second vertex, ahead of the full shading: the
// cell's mean where the shading below would stop the path there (a rough, non-emissive,
// opaque surface, a bounce longer than the cell, a cell with enough samples), without the shading
// normal and base colour texel that such a path never uses. The same cell, the same test.
// `cell`: the hit's cell (cache_cell), found a few hits ahead so its slot is prefetched.
bool Renderer::Impl::cache_answer(const SurfaceHit& h, const RadianceCache::Cell& cell,
                                  Vec3& lc) const {
  const TriangleMesh& mesh = *instances[h.instance_id].mesh;
  const Material& mat = material_of(mesh, h.prim_id);
  if (luminance(mat.emission) > 0 || mat.transmission > 0) return false;
  float metallic;
  const float roughness = roughness_at(
      mat, [&] { return uv_at(mesh, h.prim_id, h.u, h.v); }, metallic);
  if (!(std::max(roughness * roughness, min_alpha) >= cache_alpha_second)) return false;
  return h.t >= cell.size && radiance_cache.lookup(cell.key, lc);
}

RadianceCache::Cell Renderer::Impl::cache_cell(const SurfaceHit& h, const Ray& ray) const {
  Surface sf;
  surface_geometry(h, ray, sf);
  const RadianceCache::Cell cell = radiance_cache.cell(sf.p, sf.ng);
  radiance_cache.prefetch(cell.key);
  return cell;
}

}  // namespace kestrel
