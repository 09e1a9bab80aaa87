// The surface at a hit, as the path tracer's shading reads it: prefetching what it reads
// ahead of the shading loop (indices, vertices, texels), the hit's geometry, its material's
// roughness and its full BSDF parameters.
#include <algorithm>
#include <cmath>

#include "render/bsdf.h"
#include "render/renderer_impl.h"

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
  const Texture* t = texture(material_of(m, h.prim_id).base_color_texture);
  if (!t) return;
  const Vec2 uv = uv_at(m, h.prim_id, h.u, h.v);
  const float u = uv.x, v = uv.y;
  const float x = (u - std::floor(u)) * float(t->width), y = (v - std::floor(v)) * float(t->height);
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
  if (!is.identity) p0 = is.xf.point(p0), p1 = is.xf.point(p1), p2 = is.xf.point(p2);
  sf.p = p0 * b0 + p1 * h.u + p2 * h.v;
  const Vec3 wo = sf.wo = -ray.dir;
  Vec3 ng = cross(p1 - p0, p2 - p0);
  const float ng_len = length(ng);
  ng = ng_len > 0 ? ng * (1.0f / ng_len) : -wo;
  sf.cos_hit = dot(ng, wo);
  sf.ng = sf.cos_hit < 0 ? -ng : ng;
  sf.mat = &material_of(mesh, h.prim_id);
}

// The material's roughness in [0, 1] at uv (its metallic-roughness texture's G scales it) and
// its metallic factor (the texture's B).
float Renderer::Impl::roughness_at(const Material& mat, Vec2 uv, float& metallic) const {
  float roughness = mat.roughness;
  metallic = mat.metallic;
  if (const Texture* t = texture(mat.metallic_roughness_texture)) {
    float c[4];
    sample_texture(*t, uv, false, c);
    roughness *= c[1];
    metallic *= c[2];
  }
  metallic = std::clamp(metallic, 0.0f, 1.0f);
  return std::clamp(roughness, 0.0f, 1.0f);
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
  const Vec2 uv = sf.uv = uv_at(mesh, h.prim_id, h.u, h.v);
  const Material& mat = *sf.mat;
  BsdfParams& bp = sf.bp;
  bp.base = mat.base_color;
  if (const Texture* t = texture(mat.base_color_texture)) {
    float c[4];
    sample_texture(*t, uv, true, c);
    bp.base = bp.base * Vec3{c[0], c[1], c[2]};
  }
  bp.base = min(max(bp.base, Vec3{0, 0, 0}), Vec3{1, 1, 1});
  const float roughness = roughness_at(mat, uv, bp.metallic);
  bp.alpha = std::max(roughness * roughness, min_alpha);
  bp.specular = std::clamp(mat.specular, 0.0f, 1.0f);
  sf.ns = ns, sf.roughness = roughness;
  return sf;
}

}  // namespace kestrel
