// The one BSDF of the renderer: kestrel's metallic-roughness material at a shading point,
// in the local frame (z = shading normal, wo.z > 0). Lobes:
//   diffuse   (1 - metallic) * base / pi * (1 - s F_d(cos_i)) (1 - s F_d(cos_o))   [Lambertian]
//   specular  F(wi.h) D(h) G2(wo, wi) / (4 cos_o cos_i)                           [GGX]
// with F = (1 - metallic) s Schlick(0.04) + metallic Schlick(base) (dielectric coat / rough
// conductor), D the GGX (Trowbridge-Reitz) distribution, G2 the height-correlated Smith term.
// The specular lobe is sampled with Heitz 2018's visible normals, the diffuse lobe with a
// cosine; one pdf covers both (the mixture), so eval/pdf/sample agree (tests/render).
#pragma once
#include <algorithm>
#include <cmath>

#include "core/vec.h"
#include "render/fast_math.h"

namespace kestrel::render {

inline constexpr float pi = 3.14159265358979323846f;
inline constexpr float min_alpha = 1e-3f;

struct BsdfParams {
  Vec3 base{0.8f, 0.8f, 0.8f};
  float metallic = 0;
  float alpha = 1;     ///< GGX alpha = perceptual roughness^2, at least min_alpha
  float specular = 0;  ///< dielectric coat weight
};

inline float luminance(Vec3 c) {
  return 0.2126f * c.x + 0.7152f * c.y + 0.0722f * c.z;
}
inline float schlick_weight(float c) {
  const float m = std::clamp(1.0f - c, 0.0f, 1.0f);
  const float m2 = m * m;
  return m2 * m2 * m;
}

inline float ggx_d(float alpha, Vec3 h) {
  const float a2 = alpha * alpha;
  const float t = h.z * h.z * (a2 - 1.0f) + 1.0f;
  return a2 / (pi * t * t);
}
inline float ggx_lambda(float alpha, Vec3 w) {
  const float z2 = w.z * w.z;
  if (z2 <= 0) return 1e30f;
  const float tan2 = std::max(0.0f, 1.0f - z2) / z2;
  return 0.5f * (-1.0f + std::sqrt(1.0f + alpha * alpha * tan2));
}
inline float ggx_g1(float alpha, Vec3 w) {
  return 1.0f / (1.0f + ggx_lambda(alpha, w));
}

/// Visible-normal sample (Heitz 2018, "Sampling the GGX Distribution of Visible Normals").
inline Vec3 sample_ggx_vndf(float alpha, Vec3 wo, float u1, float u2) {
  const Vec3 vh = normalize(Vec3{alpha * wo.x, alpha * wo.y, wo.z});
  const float lensq = vh.x * vh.x + vh.y * vh.y;
  const Vec3 t1 = lensq > 0 ? Vec3{-vh.y, vh.x, 0} * (1.0f / std::sqrt(lensq)) : Vec3{1, 0, 0};
  const Vec3 t2 = cross(vh, t1);
  const float r = std::sqrt(u1);
  float sin_phi, cos_phi;  // of phi = 2 pi u2
  sincos_2pi(u2, sin_phi, cos_phi);
  const float p1 = r * cos_phi;
  float p2 = r * sin_phi;
  const float s = 0.5f * (1.0f + vh.z);
  p2 = (1.0f - s) * std::sqrt(std::max(0.0f, 1.0f - p1 * p1)) + s * p2;
  const Vec3 nh = t1 * p1 + t2 * p2 + vh * std::sqrt(std::max(0.0f, 1.0f - p1 * p1 - p2 * p2));
  return normalize(Vec3{alpha * nh.x, alpha * nh.y, std::max(1e-6f, nh.z)});
}

inline Vec3 fresnel(const BsdfParams& p, float cos_theta) {
  const float w = schlick_weight(cos_theta);
  const float dielectric = p.specular * (0.04f + 0.96f * w);
  const Vec3 conductor = p.base + (Vec3{1, 1, 1} - p.base) * w;
  return Vec3{dielectric, dielectric, dielectric} * (1.0f - p.metallic) + conductor * p.metallic;
}

/// Probability of sampling the specular lobe for this wo (a function of wo only).
inline float specular_probability(const BsdfParams& p, Vec3 wo) {
  const float ws = luminance(fresnel(p, wo.z));
  const float wd = (1.0f - p.metallic) * luminance(p.base) *
                   (1.0f - p.specular * (0.04f + 0.96f * schlick_weight(wo.z)));
  if (ws <= 0) return 0.0f;
  if (wd <= 0) return 1.0f;
  return std::clamp(ws / (ws + wd), 0.1f, 0.9f);
}

struct BsdfSample {
  Vec3 wi;
  Vec3 weight;  ///< f * cos / pdf
  float pdf = 0;
};

/// The BSDF at one shading point: what its value and pdf share for one wo (the diffuse
/// lobe's Fresnel factor, Smith's Lambda, the specular lobe's probability) is computed once,
/// and a light sample and a BSDF sample there reuse it. The free functions below are the same
/// function for one call.
struct BsdfAt {
  const BsdfParams& p;
  Vec3 wo;
  bool above = false;    ///< not wo.z <= 0 (otherwise everything is zero)
  bool glossy = false;   ///< the specular lobe has a value (metallic or a dielectric coat)
  float fd_o = 0;        ///< the diffuse lobe's Fresnel factor at wo
  float lambda_o = 0;    ///< Smith's Lambda at wo
  float four_cos_o = 0;  ///< 4 wo.z
  float ps = 0;          ///< specular_probability(p, wo), when with_pdf

  BsdfAt(const BsdfParams& params, Vec3 w, bool with_pdf = true) : p(params), wo(w) {
    above = !(wo.z <= 0);
    if (!above) return;
    fd_o = 1.0f - p.specular * (0.04f + 0.96f * schlick_weight(wo.z));
    glossy = p.metallic > 0 || p.specular > 0;
    if (!glossy) return;  // Lambertian: no specular lobe, ps = 0 (what the lines below give)
    lambda_o = ggx_lambda(p.alpha, wo);
    four_cos_o = 4.0f * wo.z;
    if (with_pdf) ps = specular_probability(p, wo);
  }

  /// f(wo, wi) * cos(wi) and, when `pdf` is given, the pdf of sampling wi (the mixture of the
  /// cosine and the visible-normal lobes); zero below the surface.
  void eval(Vec3 wi, Vec3& f, float* pdf) const {
    f = {0, 0, 0};
    if (pdf) *pdf = 0;
    if (!above || wi.z <= 0) return;
    if (p.metallic < 1.0f) {
      const float fd = (1.0f - p.specular * (0.04f + 0.96f * schlick_weight(wi.z))) * fd_o;
      f = p.base * ((1.0f - p.metallic) * fd / pi * wi.z);
    }
    if (pdf) *pdf = (1.0f - ps) * wi.z / pi;
    const bool spec_pdf = pdf && ps > 0;
    if (!glossy && !spec_pdf) return;
    const Vec3 h = normalize(wo + wi);
    const float d = ggx_d(p.alpha, h);
    if (glossy) {
      const float g2 = 1.0f / (1.0f + lambda_o + ggx_lambda(p.alpha, wi));
      f = f + fresnel(p, dot(wi, h)) * (d * g2 / four_cos_o);
    }
    if (spec_pdf) *pdf += ps * (1.0f / (1.0f + lambda_o)) * d / four_cos_o;
  }

  /// Samples wi; false when the sample leaves no contribution (below the surface).
  /// `cosine`: the cosine lobe's direction for (u1, u2) where the caller has it (the lines
  /// below give it; render::PathDraws makes it ahead), or null.
  bool sample(float u0, float u1, float u2, const Vec3* cosine, BsdfSample& s) const {
    if (!above) return false;
    if (u0 < ps) {
      const Vec3 h = sample_ggx_vndf(p.alpha, wo, u1, u2);
      s.wi = h * (2.0f * dot(wo, h)) - wo;
    } else if (cosine) {
      s.wi = *cosine;
    } else {
      const float r = std::sqrt(u1);
      float sin_phi, cos_phi;  // of phi = 2 pi u2
      sincos_2pi(u2, sin_phi, cos_phi);
      s.wi = Vec3{r * cos_phi, r * sin_phi, std::sqrt(std::max(0.0f, 1.0f - u1))};
    }
    if (s.wi.z <= 0) return false;
    Vec3 f;
    eval(s.wi, f, &s.pdf);
    if (!(s.pdf > 0)) return false;
    s.weight = f * (1.0f / s.pdf);
    return true;
  }
};

/// f(wo, wi) * cos(wi); zero below the surface.
inline Vec3 bsdf_eval(const BsdfParams& p, Vec3 wo, Vec3 wi) {
  Vec3 f;
  BsdfAt(p, wo, false).eval(wi, f, nullptr);
  return f;
}

inline float bsdf_pdf(const BsdfParams& p, Vec3 wo, Vec3 wi) {
  Vec3 f;
  float pdf;
  BsdfAt(p, wo).eval(wi, f, &pdf);
  return pdf;
}

/// Samples wi; false when the sample leaves no contribution (below the surface).
inline bool bsdf_sample(const BsdfParams& p, Vec3 wo, float u0, float u1, float u2, BsdfSample& s) {
  return BsdfAt(p, wo).sample(u0, u1, u2, nullptr, s);
}

/// An orthonormal basis around n (Duff et al. 2017).
struct Basis {
  Vec3 t, b, n;
  explicit Basis(Vec3 nn) : n(nn) {
    const float sign = std::copysign(1.0f, n.z);
    const float a = -1.0f / (sign + n.z);
    const float bb = n.x * n.y * a;
    t = Vec3{1.0f + sign * n.x * n.x * a, sign * bb, -sign * n.x};
    b = Vec3{bb, sign + n.y * n.y * a, -n.y};
  }
  Vec3 to_local(Vec3 v) const { return {dot(v, t), dot(v, b), dot(v, n)}; }
  Vec3 to_world(Vec3 v) const { return t * v.x + b * v.y + n * v.z; }
};

}  // namespace kestrel::render
