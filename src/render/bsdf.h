// The one BSDF of the renderer: kestrel's metallic-roughness material at a shading point,
// in the local frame (z = shading normal, wo.z > 0). Lobes, with k = (1 - metallic) and t the
// transmission weight:
//   diffuse   k (1 - t) base / pi (1 - s F_d(cos_i)) (1 - s F_d(cos_o))        [Lambertian]
//   specular  F(wi.h) D(h) G2(wo, wi) / (4 cos_o cos_i)                        [GGX]
//   glass     k t: a rough dielectric interface (Walter et al. 2007): reflection
//             F_r D G2 / (4 cos_o cos_i), and transmission base (1 - F_r) D G2 |wi.h| |wo.h|
//             / (cos_o |cos_i| (wi.h + wo.h / eta)^2 eta^2) below the surface (radiance),
//             or, thin-walled, base (1 - F_r) times the reflection lobe mirrored below
//             (light goes straight on); F_r the exact dielectric Fresnel at eta
// with F = k (1 - t) s Schlick(F0) + metallic Schlick(base) (F0 = 0.04 at IOR 1.5) (dielectric coat
// / rough conductor), D the GGX (Trowbridge-Reitz) distribution, G2 the height-correlated Smith
// term. The specular and glass lobes are sampled with Heitz 2018's visible normals, the diffuse
// lobe with a cosine; one pdf covers all (the mixture), so eval/pdf/sample agree (tests/render).
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
  float f0 = 0.04f;    ///< the coat's reflectance at normal incidence, ((ior - 1) / (ior + 1))^2
  /// Glass: the weight of the dielectric interface within the non-metallic part, instead of the
  /// coated diffuse base. 0 leaves the BSDF a reflection (nothing below the surface).
  float transmission = 0;
  float eta = 1.5f;   ///< glass: IOR beyond the surface / IOR on wo's side (>= 1 when thin)
  bool thin = false;  ///< glass: thin-walled (no bending: a sheet, a window pane)
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
  const float dielectric = p.specular * (p.f0 + (1.0f - p.f0) * w);
  const Vec3 conductor = p.base + (Vec3{1, 1, 1} - p.base) * w;
  return Vec3{dielectric, dielectric, dielectric} *
             ((1.0f - p.metallic) * (1.0f - p.transmission)) +
         conductor * p.metallic;
}

/// Unpolarised Fresnel reflectance of a dielectric interface, light arriving at cos_i > 0 on
/// the side whose IOR is 1 / eta of the other's; 1 under total internal reflection.
inline float fresnel_dielectric(float cos_i, float eta) {
  const float sin2_t = std::max(0.0f, 1.0f - cos_i * cos_i) / (eta * eta);
  if (sin2_t >= 1.0f) return 1.0f;
  const float cos_t = std::sqrt(1.0f - sin2_t);
  const float r_par = (eta * cos_i - cos_t) / (eta * cos_i + cos_t);
  const float r_perp = (cos_i - eta * cos_t) / (cos_i + eta * cos_t);
  return 0.5f * (r_par * r_par + r_perp * r_perp);
}

/// Probability of sampling the specular lobe for this wo (a function of wo only).
inline float specular_probability(const BsdfParams& p, Vec3 wo) {
  const float ws = luminance(fresnel(p, wo.z));
  const float wd = (1.0f - p.metallic) * (1.0f - p.transmission) * luminance(p.base) *
                   (1.0f - p.specular * (p.f0 + (1.0f - p.f0) * schlick_weight(wo.z)));
  if (ws <= 0) return 0.0f;
  if (wd <= 0) return 1.0f;
  return std::clamp(ws / (ws + wd), 0.1f, 0.9f);
}

/// With a glass lobe (transmission > 0): the probabilities of sampling the specular and the
/// glass lobes (the diffuse lobe has the rest), by each lobe's share of the reflectance at wo,
/// at least 0.1 for a lobe that has a value.
[[gnu::noinline]] inline void glass_probabilities(const BsdfParams& p, Vec3 wo, float& ps,
                                                  float& pg) {
  const float k = 1.0f - p.metallic;
  const float fg = fresnel_dielectric(wo.z, p.eta);
  float w[3] = {luminance(fresnel(p, wo.z)),
                k * p.transmission * (fg + (1.0f - fg) * luminance(p.base)),
                k * (1.0f - p.transmission) * luminance(p.base) *
                    (1.0f - p.specular * (p.f0 + (1.0f - p.f0) * schlick_weight(wo.z)))};
  const float total = w[0] + w[1] + w[2];
  if (!(total > 0)) {
    ps = 0, pg = 1;
    return;
  }
  float sum = 0;
  for (float& x : w) sum += x = x > 0 ? std::max(x / total, 0.1f) : 0.0f;
  ps = w[0] / sum, pg = w[1] / sum;
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
  bool glass = false;    ///< the glass lobe has a value
  float pg = 0;          ///< the glass lobe's probability (glass_probabilities), when with_pdf
  float kd = 0;          ///< the diffuse lobe's weight, (1 - metallic) (1 - transmission)

  BsdfAt(const BsdfParams& params, Vec3 w, bool with_pdf = true) : p(params), wo(w) {
    above = !(wo.z <= 0);
    if (!above) return;
    fd_o = 1.0f - p.specular * (p.f0 + (1.0f - p.f0) * schlick_weight(wo.z));
    kd = (1.0f - p.metallic) * (1.0f - p.transmission);
    glossy = p.metallic > 0 || p.specular > 0;
    glass = p.transmission > 0 && p.metallic < 1;
    if (!glossy && !glass) return;  // Lambertian: no specular lobe, ps = 0
    lambda_o = ggx_lambda(p.alpha, wo);
    four_cos_o = 4.0f * wo.z;
    if (!with_pdf) return;
    if (glass)
      glass_probabilities(p, wo, ps, pg);
    else
      ps = specular_probability(p, wo);
  }

  /// The glass lobe at wi (f * |cos(wi)|, and its share of the pdf when `pdf`), added. (Out
  /// of line, as the other glass parts: opaque surfaces' shading keeps its inlined code.)
  [[gnu::noinline]] void eval_glass(Vec3 wi, Vec3& f, float* pdf) const {
    const float g1_o = 1.0f / (1.0f + lambda_o), k = (1.0f - p.metallic) * p.transmission;
    const bool reflect = wi.z > 0;
    if (reflect || p.thin) {  // thin: the transmitted direction is the reflection mirrored
      const Vec3 wr{wi.x, wi.y, std::fabs(wi.z)};
      const Vec3 h = normalize(wo + wr);
      const float fr = fresnel_dielectric(dot(wo, h), p.eta), d = ggx_d(p.alpha, h);
      const float share = reflect ? fr : 1.0f - fr;
      const float g2 = 1.0f / (1.0f + lambda_o + ggx_lambda(p.alpha, wr));
      const float v = k * share * d * g2 / four_cos_o;
      f = f + (reflect ? Vec3{v, v, v} : p.base * v);
      if (pdf) *pdf += pg * share * g1_o * d / four_cos_o;
      return;
    }
    // Refraction: the generalised half vector, on wo's side; microfacets facing both ways only.
    Vec3 h = wo + wi * p.eta;
    const float len2 = dot(h, h);
    if (!(len2 > 0)) return;
    h = h * (1.0f / std::sqrt(len2));
    if (h.z < 0) h = -h;
    const float oh = dot(wo, h), ih = dot(wi, h);
    if (!(oh > 0 && ih < 0)) return;
    const float fr = fresnel_dielectric(oh, p.eta);
    if (!(fr < 1.0f)) return;
    const float d = ggx_d(p.alpha, h), denom = ih + oh / p.eta, denom2 = denom * denom;
    if (!(denom2 > 0)) return;
    const float g2 = 1.0f / (1.0f + lambda_o + ggx_lambda(p.alpha, wi));
    const float jac = -ih / denom2;  // |wi.h| / (wi.h + wo.h / eta)^2: dh / dwi
    const float v =
        k * (1.0f - fr) * d * g2 * oh * jac / (wo.z * p.eta * p.eta);  // radiance: / eta^2
    f = f + p.base * v;
    if (pdf) *pdf += pg * (1.0f - fr) * g1_o * oh * d / wo.z * jac;
  }

  /// f(wo, wi) * cos(wi) and, when `pdf` is given, the pdf of sampling wi (the mixture of the
  /// cosine and the visible-normal lobes); below the surface, the glass lobe's transmission alone.
  void eval(Vec3 wi, Vec3& f, float* pdf) const {
    f = {0, 0, 0};
    if (pdf) *pdf = 0;
    if (!above) return;
    if (!(wi.z > 0)) {  // below: the glass lobe's transmission alone
      if (glass && wi.z < 0) eval_glass(wi, f, pdf);
      return;
    }
    if (p.metallic < 1.0f) {
      const float fd = (1.0f - p.specular * (p.f0 + (1.0f - p.f0) * schlick_weight(wi.z))) * fd_o;
      f = p.base * (kd * fd / pi * wi.z);
    }
    if (pdf) *pdf = (1.0f - ps - pg) * wi.z / pi;
    const bool spec_pdf = pdf && ps > 0;
    if (glossy || spec_pdf) {
      const Vec3 h = normalize(wo + wi);
      const float d = ggx_d(p.alpha, h);
      if (glossy) {
        const float g2 = 1.0f / (1.0f + lambda_o + ggx_lambda(p.alpha, wi));
        f = f + fresnel(p, dot(wi, h)) * (d * g2 / four_cos_o);
      }
      if (spec_pdf) *pdf += ps * (1.0f / (1.0f + lambda_o)) * d / four_cos_o;
    }
    if (glass) eval_glass(wi, f, pdf);
  }

  /// Samples wi; false when the sample leaves no contribution (below the surface, but for glass).
  /// `cosine`: the cosine lobe's direction for (u1, u2) where the caller has it (the lines
  /// below give it; render::PathDraws makes it ahead), or null.
  bool sample(float u0, float u1, float u2, const Vec3* cosine, BsdfSample& s) const {
    if (!above) return false;
    if (u0 < ps) {
      const Vec3 h = sample_ggx_vndf(p.alpha, wo, u1, u2);
      s.wi = h * (2.0f * dot(wo, h)) - wo;
      if (!(s.wi.z > 0)) return false;  // (below is the glass lobe's, when there is one)
    } else if (u0 < ps + pg) {
      s.wi = sample_glass((u0 - ps) / pg, u1, u2);  // z = 0: on the wrong side
    } else if (cosine) {
      s.wi = *cosine;
    } else {
      const float r = std::sqrt(u1);
      float sin_phi, cos_phi;  // of phi = 2 pi u2
      sincos_2pi(u2, sin_phi, cos_phi);
      s.wi = Vec3{r * cos_phi, r * sin_phi, std::sqrt(std::max(0.0f, 1.0f - u1))};
    }
    if (!(s.wi.z > 0) && !(s.wi.z < 0 && u0 >= ps)) return false;
    Vec3 f;
    eval(s.wi, f, &s.pdf);
    if (!(s.pdf > 0)) return false;
    s.weight = f * (1.0f / s.pdf);
    return true;
  }

  /// The glass lobe's direction for u in [0, 1): a visible normal, then reflection with
  /// probability F_r, else refraction (thin: the reflection mirrored below); a direction on
  /// the wrong side for its kind (z = 0) when the microfacet sends it there.
  [[gnu::noinline]] Vec3 sample_glass(float u, float u1, float u2) const {
    const Vec3 h = sample_ggx_vndf(p.alpha, wo, u1, u2);
    const float oh = dot(wo, h), fr = fresnel_dielectric(oh, p.eta);
    Vec3 wi = h * (2.0f * oh) - wo;
    if (u < fr) return wi.z > 0 ? wi : Vec3{0, 0, 0};
    if (p.thin) return wi.z > 0 ? Vec3{wi.x, wi.y, -wi.z} : Vec3{0, 0, 0};
    const float cos2_t = 1.0f - (1.0f - oh * oh) / (p.eta * p.eta);
    wi = h * (oh / p.eta - std::sqrt(std::max(0.0f, cos2_t))) - wo * (1.0f / p.eta);
    return wi.z < 0 ? wi : Vec3{0, 0, 0};
  }
};

/// f(wo, wi) * |cos(wi)|; zero below the surface unless the material is glass.
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

/// Samples wi; false when the sample leaves no contribution (below the surface, but for glass).
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
