// Materials and lights: the trailing default material and its checks, the emissive triangles
// of every instance in world space, sampled by power, the scene bounds, and next-event
// estimation's light sample at a surface (the environment, the sun or a local light).
#include <fmt/format.h>

#include <cmath>
#include <cstring>
#include <unordered_map>

#include "kestrel/error.h"
#include "kestrel/scene.h"
#include "render/bsdf.h"
#include "render/renderer_impl.h"

namespace kestrel {

using namespace render;

// A trailing "default" material (what out-of-range ids fall back to), every one checked.
void Renderer::Impl::check_materials(const std::string& source) {
  if (materials.empty() || materials.back().name != "default")
    materials.push_back(Material{.name = "default"});
  for (size_t i = 0; i < materials.size(); ++i) {
    Material& m = materials[i];
    if (!is_finite(m.base_color) || !is_finite(m.emission) || !std::isfinite(m.metallic) ||
        !std::isfinite(m.roughness) || !std::isfinite(m.specular) || !std::isfinite(m.alpha) ||
        !std::isfinite(m.normal_scale) || !std::isfinite(m.alpha_cutoff) || m.emission.x < 0 ||
        m.emission.y < 0 || m.emission.z < 0 || !std::isfinite(m.transmission) ||
        !std::isfinite(m.ior) || !is_finite(m.attenuation_color) || m.attenuation_color.x < 0 ||
        m.attenuation_color.y < 0 || m.attenuation_color.z < 0 || !(m.attenuation_distance > 0))
      throw Error(ErrorCode::invalid_argument,
                  fmt::format("{}: material {} '{}': a non-finite or negative parameter", source, i,
                              m.name));
    if (!(m.ior >= 1))
      throw Error(ErrorCode::invalid_argument,
                  fmt::format("{}: material {} '{}': index of refraction {} (at least 1)", source,
                              i, m.name, m.ior));
    m.transmission = std::clamp(m.transmission, 0.0f, 1.0f);  // shading reads it as it is
  }
}

namespace {
uint64_t mix(uint64_t h, uint64_t w) {
  h = (h ^ w) * 0x9E3779B97F4A7C15ull;
  return h ^ (h >> 29);
}
// A 64-bit fingerprint of an array's bytes, eight at a time.
template <class T>
uint64_t hash_array(uint64_t h, const std::vector<T>& v) {
  const size_t bytes = v.size() * sizeof(T);
  const auto* p = reinterpret_cast<const unsigned char*>(v.data());
  size_t i = 0;
  for (; i + 8 <= bytes; i += 8) {
    uint64_t w;
    std::memcpy(&w, p + i, 8);
    h = mix(h, w);
  }
  uint64_t w = 0;
  if (bytes > i) std::memcpy(&w, p + i, bytes - i);
  return mix(mix(h, w), bytes);
}
}  // namespace

// Each triangle's mean emitted luminance where its emission is textured (0 elsewhere),
// remembered while the mesh's uvs, indices and material ids, the materials' emission and the
// textures stay the same (`glow_key`): a glTF asset commits every frame, animated or not.
const std::vector<float>& Renderer::Impl::textured_emission(const TriangleMesh& mesh,
                                                            uint64_t glow_key) {
  uint64_t key = hash_array(glow_key, mesh.uvs);
  key = hash_array(key, mesh.indices);
  key = hash_array(key, mesh.material_ids);
  GlowCache& c = glow_cache[&mesh];
  c.seen = true;
  if (c.key == key && c.mean.size() == mesh.triangle_count()) return c.mean;
  c.key = key;
  c.mean.assign(mesh.triangle_count(), 0.0f);
  for (uint32_t p = 0; p < mesh.triangle_count(); ++p) {
    const Material& m = material_of(mesh, p);
    if (const Texture* t = texture(m.emission_texture); t && luminance(m.emission) > 0)
      c.mean[p] = luminance(m.emission * mean_texel(*t, mesh, p));
  }
  return c.mean;
}

void Renderer::Impl::sync_lights() {
  // Emissive triangles by mesh, then world-space light triangles for every instance.
  std::unordered_map<const TriangleMesh*, uint32_t> key_of;
  // What textured emission depends on beyond a mesh: the materials' emission and textures.
  bool glow = false;
  uint64_t glow_key = 0;
  for (const Material& m : materials) {
    glow |= luminance(m.emission) > 0 && texture(m.emission_texture);
    const float e[3] = {m.emission.x, m.emission.y, m.emission.z};
    uint32_t w[4] = {uint32_t(m.emission_texture), 0, 0, 0};
    std::memcpy(&w[1], e, sizeof e);
    glow_key = mix(mix(glow_key, uint64_t(w[0]) << 32 | w[1]), uint64_t(w[2]) << 32 | w[3]);
  }
  for (const Texture& t : scene->textures()) {  // its place, size and 64 of its texels
    glow_key = mix(mix(glow_key, reinterpret_cast<uintptr_t>(t.rgba.data())),
                   uint64_t(uint32_t(t.width)) << 32 | uint32_t(t.height));
    for (size_t k = 0, n = t.rgba.size() / 4; n > 0 && k < 64; ++k) {
      uint32_t texel;
      std::memcpy(&texel, &t.rgba[(k * n / 64) * 4], 4);
      glow_key = mix(glow_key, texel);
    }
  }
  for (auto& [mesh, c] : glow_cache) c.seen = false;
  emissive_rank.clear();
  lights.clear();
  std::vector<float> power;
  // Per mesh key, per emissive triangle (by rank): its mean emitted luminance.
  std::vector<std::vector<float>> radiance;
  bounds = Bounds3{};
  lit_by_emitters = false;
  for (uint32_t i = 0; i < instances.size(); ++i) {
    InstanceShade& is = instances[i];
    if (!is.mesh) continue;
    auto [it, fresh] = key_of.try_emplace(is.mesh, uint32_t(emissive_rank.size()));
    if (fresh) {
      std::vector<int32_t> rank(is.mesh->triangle_count(), -1);
      std::vector<float> mean;
      const std::vector<float>* textured = glow ? &textured_emission(*is.mesh, glow_key) : nullptr;
      for (uint32_t p = 0; p < rank.size(); ++p) {
        const Material& m = material_of(*is.mesh, p);
        if (!(luminance(m.emission) > 0) || !valid_triangle(*is.mesh, p)) continue;
        // A textured emitter black all over this triangle is not a light (a BSDF ray that
        // hits it takes its emission with MIS weight 1).
        const float lum = texture(m.emission_texture) ? (*textured)[p] : luminance(m.emission);
        if (!(lum > 0)) continue;
        rank[p] = int32_t(mean.size());
        mean.push_back(lum);
      }
      emissive_rank.push_back(std::move(rank));
      radiance.push_back(std::move(mean));
    }
    is.mesh_key = it->second;
    is.light_base = uint32_t(lights.size());
    const std::vector<int32_t>& rank = emissive_rank[is.mesh_key];
    for (uint32_t p = 0; p < rank.size(); ++p) {
      if (rank[p] < 0) continue;
      Vec3 p0, p1, p2;
      world_triangle(is, p, p0, p1, p2);
      const float area = 0.5f * length(cross(p1 - p0, p2 - p0));
      const Material* mat = &material_of(*is.mesh, p);
      lights.push_back({i, p, p0, p1 - p0, p2 - p0, area, normalize(cross(p1 - p0, p2 - p0)), mat});
      const float w = area > 0 ? radiance[is.mesh_key][size_t(rank[p])] * area * 2 * pi : 0.0f;
      power.push_back(w);
      // Emission from a texture is a surface's own glow (a label, a screen, an indicator:
      // glTF models carry it routinely), not what lights the scene.
      lit_by_emitters |= w > 0 && !texture(mat->emission_texture);
    }
    const TriangleMesh& m = *is.mesh;
    for (uint32_t t = 0; t < m.triangle_count(); ++t) {
      if (!valid_triangle(m, t)) continue;
      Vec3 p0, p1, p2;
      world_triangle(is, t, p0, p1, p2);
      extend(bounds, p0), extend(bounds, p1), extend(bounds, p2);
    }
  }
  std::erase_if(glow_cache, [](const auto& entry) { return !entry.second.seen; });
  double triangle_power = 0;
  for (float w : power) triangle_power += w;
  if (!(triangle_power > 0)) lights.clear(), power.clear();
  // Punctual lights after the triangles, by power: a point light 4 pi I, a spot 2 pi (1 -
  // cos outer) I, a directional one its irradiance over the scene's cross-section.
  punctual.clear();
  const float r = is_empty(bounds) ? 1.0f : 0.5f * length(extent(bounds));
  for (const Light& l : scene->lights()) {
    if (const std::string problem = light_problem(l); !problem.empty())
      throw Error(
          ErrorCode::invalid_argument,
          fmt::format("{}: {} light '{}': {}", source(), light_type_name(l.type), l.name, problem));
    Punctual q;
    q.type = l.type, q.position = l.position, q.direction = normalize(l.direction),
    q.intensity = l.color * l.intensity;
    q.range = l.range;
    const float cos_inner = std::cos(l.inner_cone), cos_outer = std::cos(l.outer_cone);
    q.spot_scale = 1.0f / std::max(0.001f, cos_inner - cos_outer);  // glTF's smooth cone edge
    q.spot_offset = -cos_outer * q.spot_scale;
    const float lum = luminance(q.intensity);
    float w = 0;
    if (l.type == Light::Type::point)
      w = 4 * pi * lum;
    else if (l.type == Light::Type::spot)
      w = 2 * pi * (1 - cos_outer) * lum;
    else
      w = pi * r * r * lum;
    if (!(w > 0)) continue;
    lit_by_emitters = true;
    punctual.push_back(q);
    power.push_back(w);
  }
  light_dist = Distribution1D(power);
  if (light_dist.total() <= 0) lights.clear(), punctual.clear();
  // The light tree over the same local lights, unless one is directional (no position).
  light_tree.build({});
  bool directional = false;
  for (const Punctual& q : punctual) directional |= q.type == Light::Type::directional;
  if (!directional && local_light_count() > 1) {
    std::vector<LightTree::Item> items;
    items.reserve(local_light_count());
    for (size_t i = 0; i < lights.size(); ++i) {
      const LightTri& l = lights[i];
      Bounds3 b;
      extend(b, l.p0), extend(b, l.p0 + l.e1), extend(b, l.p0 + l.e2);
      items.push_back({b, power[i]});
    }
    for (size_t i = 0; i < punctual.size(); ++i) {
      Bounds3 b;
      extend(b, punctual[i].position);
      items.push_back({b, power[lights.size() + i]});
    }
    light_tree.build(items);
  }
}

// ---- next-event estimation -------------------------------------------------------------------

bool Renderer::Impl::punctual_light(const Punctual& q, Vec3 origin, Vec3& wi, Vec3& dir, Vec3& le,
                                    float& tmax) const {
  if (q.type == Light::Type::directional) {
    wi = dir = -q.direction;
    le = q.intensity;  // irradiance
    tmax = INFINITY;
    return true;
  }
  dir = q.position - origin;
  const float dist2 = dot(dir, dir);
  if (!(dist2 > 0)) return false;
  const float dist = std::sqrt(dist2);
  wi = dir * (1.0f / dist);
  float k = 1.0f / dist2;
  if (q.range > 0) {  // glTF's recommended window: (1 - (d / range)^4)^2, clamped
    const float x = dist / q.range, x4 = x * x * x * x;
    const float win = std::clamp(1 - x4, 0.0f, 1.0f);
    k *= win * win;
  }
  if (q.type == Light::Type::spot) {
    const float a = std::clamp(dot(q.direction, -wi) * q.spot_scale + q.spot_offset, 0.0f, 1.0f);
    k *= a * a;
  }
  le = q.intensity * k;
  tmax = 1.0f - 1e-3f;
  return true;
}

Vec3 Renderer::Impl::sun_sample(float u1, float u2) const {
  const float cos_t = 1 - u1 * (1 - sun_cos_max),
              sin_t = std::sqrt(std::max(0.0f, 1 - cos_t * cos_t));
  float sin_phi, cos_phi;  // of phi = 2 pi u2
  sincos_2pi(u2, sin_phi, cos_phi);
  return sun_frame.to_world({sin_t * cos_phi, sin_t * sin_phi, cos_t});
}

// One light sample at a surface: the environment, the sun, or a local light (an emissive
// triangle or a punctual light, by power); MIS weighted against the BSDF except for punctual
// lights (deltas): the shadow ray to trace and what it adds when unblocked.
bool Renderer::Impl::sample_light(const Surface& sf, const Basis& frame, const BsdfAt& bsdf,
                                  const Vec3& origin, const Vec3& throughput, Rng& rng, bool tree,
                                  bool env, Ray& shadow, Vec3& contribution, const PathDraws* pre,
                                  int j) const {
  const Vec3 &ng = sf.ng, &ns = sf.ns;
  float ul, u1, u2;
  if (pre) {  // the same three draws, made ahead
    ul = pre->ul[j], u1 = pre->u1[j], u2 = pre->u2[j];
    rng.set_state(pre->state3[j]);
  } else {
    ul = rng.uniform(), u1 = rng.uniform(), u2 = rng.uniform();
  }
  // Without the environment: ul in [p_env, 1), each other light's pick scaled by `scale`.
  const float scale = nee_scale(env);
  if (!env) ul = std::min(p_env + ul * (1.0f - p_env), 0x1.fffffep-1f);
  Vec3 wi, le;
  float pdf = 0, tmax = INFINITY;
  bool delta = false;  // a punctual light: pdf is its pick probability, no MIS
  Vec3 dir;
  if (ul < p_env) {
    float epdf;
    wi = env_sample(u1, u2, ns, epdf);
    pdf = p_env * epdf;
    le = env_radiance(wi);
    dir = wi;
  } else if (ul < p_env + p_sun) {  // the sun: uniform in its cone (p_sun > 0: in the draws)
    wi = pre ? Vec3{pre->sx[j], pre->sy[j], pre->sz[j]} : sun_sample(u1, u2);
    pdf = p_sun / sun_solid_angle * scale;
    le = sun_radiance;
    dir = wi;
  } else {
    LightDraw d =
        local_light_sample(origin, tree, (ul - p_env - p_sun) / (1 - p_env - p_sun), u1, u2);
    d.pdf *= scale;
    const size_t li = d.y.id;
    if (li >= lights.size()) {  // a punctual light: a delta, no MIS
      pdf = d.pdf;              // a probability, not a density
      delta = true;
      if (!punctual_light(punctual[li - lights.size()], origin, wi, dir, le, tmax)) return false;
    } else {
      const LightTri& l = lights[li];
      const float lb1 = d.y.v.x, lb2 = d.y.v.y;  // weights of vertices 1 and 2
      const Vec3 q = l.p0 + l.e1 * lb1 + l.e2 * lb2;
      dir = q - origin;
      const float dist2 = dot(dir, dir);
      wi = dir * (1.0f / std::sqrt(dist2));
      const float cos_l = std::fabs(dot(l.normal, wi));
      le = light_emission(l, lb1, lb2);
      pdf = cos_l > 0 && l.area > 0 ? d.pdf * dist2 / cos_l : 0.0f;  // area -> solid angle
      tmax = 1.0f - 1e-3f;
    }
  }
  if (!(pdf > 0 && dot(wi, ng) > 0 && luminance(le) > 0)) return false;
  Vec3 f;
  float bpdf;
  bsdf.eval(frame.to_local(wi), f, delta ? nullptr : &bpdf);
  if (!(luminance(f) > 0)) return false;
  const float w = delta ? 1.0f : pdf * pdf / (pdf * pdf + bpdf * bpdf);
  shadow = Ray{origin, dir, 0.0f, tmax};
  contribution = throughput * f * le * (w / pdf);
  return true;
}

}  // namespace kestrel
