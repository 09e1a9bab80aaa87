// The non-neural baselines: SVGF-like (Schied et al. 2017), real-time (vectorised per ISA,
// parallel by rows), beside its plain scalar definition (the tests' oracle), and the
// edge-avoiding a-trous filter (Dammertz et al. 2010). Planes as gather() makes them
// (colour 0-2, albedo 3-5, normal 6-8, depth 9, roughness 10, motion 11-12), unpadded.
#pragma once
#include <vector>

#include "denoise/neural.h"
#include "kestrel/image.h"

namespace kestrel::denoise {

/// One variance-guided a-trous pass of SVGF-like over rows [y0, y1): 3x3 taps at +-dilation,
/// equal weights (taps outside the image are skipped, not clamped),
///   out = sum w x(q) / sum w,  var_out = sum w^2 var(q) / (sum w)^2,  lum_out = luminance(out),
///   w = exp(sigma_n (c - 1) - |l - l(q)| inv_l - |z - z(q)| / (sigma_z |gx dx + gy dy| + e)),
/// e = 1e-3 max(z, kMinDepth); inv_l = 1 / (sigma_l sqrt(g) + 1e-4), g the 3x3 (1/4, 1/2, 1/4)
/// blur of var (taps outside the image skipped, weights renormalised); c = 1 where the pixel
/// has no normal, else max(0, n . n(q)) (exp(sigma_n (c - 1)) is SVGF's c^sigma_n with
/// log c ~ c - 1); w = 0 where q is demodulated otherwise than the pixel (`black` differs:
/// radiance and irradiance do not mix). SVGF (Schied et al. 2017) takes 5x5 taps of the B3
/// spline: 2.8x the work, and measured no better (docs/denoiser.md).
struct SvgfPass {
  const float* x[3] = {};
  const float* lum = nullptr;  ///< luminance of x
  const float* var = nullptr;  ///< variance of the luminance
  const float* z = nullptr;
  const float* n[3] = {};
  const float* gx = nullptr;  ///< screen-space depth gradient (central differences)
  const float* gy = nullptr;
  const float* black = nullptr;         ///< 1 where not demodulated (svgf_black), else 0
  const uint8_t* black_rows = nullptr;  ///< per row: whether it holds a black pixel
  float* out[3] = {};
  float* lum_out = nullptr;
  float* var_out = nullptr;
  int width = 0, height = 0, dilation = 1;
  float sigma_l = 4.0f, sigma_z = 1.0f;
};

/// SVGF's spatial variance estimate for short histories, rows [y0, y1): where len < 4,
/// out = max(0, E[m2] - E[m1]^2) * 4 / len over a 7x7 window weighted by
/// exp(-|z - z(q)| / max(z, 1e-3) / 0.05) * max(0, n . n(q))^32 (+1 at the centre);
/// elsewhere out = var.
struct SvgfVariance {
  const float *m1 = nullptr, *m2 = nullptr, *len = nullptr, *var = nullptr, *z = nullptr;
  const float* n[3] = {};
  float* out = nullptr;
  int width = 0, height = 0;
};

/// SVGF's temporal step for rows [y0, y1) with a history (svgf_temporal() is its scalar
/// definition): hist = irradiance 0-2, moments 3-4, length 5, depth 6, normal 7-9, black 10.
struct SvgfTemporal {
  const float* x[3] = {};  ///< demodulated colour
  const float *z = nullptr, *mx = nullptr, *my = nullptr, *black = nullptr;
  const float* n[3] = {};
  const float* const* hist = nullptr;
  float* acc[3] = {};
  float *m1 = nullptr, *m2 = nullptr, *len = nullptr, *var = nullptr;
  int width = 0, height = 0;
};

/// demodulate()'s work for rows [y0, y1) (the same values but for NaN albedo): d = albedo +
/// 0.01, or 1 where the albedo is black; x = colour / d; black flags and black rows.
struct SvgfDemodulate {
  const float* color[3] = {};
  const float* albedo[3] = {};
  float* x[3] = {};
  float* d[3] = {};
  float* black = nullptr;
  uint8_t* black_rows = nullptr;
  int width = 0;
};

struct SvgfKernels {
  void (*demodulate)(const SvgfDemodulate&, int y0, int y1);
  void (*temporal)(const SvgfTemporal&, int y0, int y1);
  void (*pass)(const SvgfPass&, int y0, int y1);
  void (*variance)(const SvgfVariance&, int y0, int y1);
};

/// The table for the ISA in force (default_isa()), and each ISA's (kernels_<isa>.cpp).
const SvgfKernels& svgf_kernels();
const SvgfKernels& svgf_kernels_sse2();
const SvgfKernels& svgf_kernels_avx2();
const SvgfKernels& svgf_kernels_avx512();

/// SVGF-like, real-time: temporal accumulation of demodulated irradiance and luminance
/// moments (motion-vector reprojection, depth / normal / demodulation test), variance from the
/// moments (7x7 estimate for histories < 4 frames), kSvgfPasses passes of SvgfPass (3x3 taps,
/// dilation 1..16, sigma_l 4, sigma_n 128, sigma_z 1); the first pass's output is the next
/// history.
/// Buffers are kept from frame to frame.
/// The a-trous passes of SVGF-like (dilation 1, 2, 4, ...).
constexpr int kSvgfPasses = 5;

struct SvgfTimes {
  double temporal = 0, variance = 0, passes = 0, output = 0;  ///< ms
};

class Svgf {
 public:
  /// Denoises one frame `g` (the inputs' 13 planes); returns the colour (3 planes, owned by
  /// this object).
  const Planes& run(const Planes& g, SvgfTimes* times = nullptr);
  /// The same, but takes g's planes: the next frame's history test reads this frame's depth
  /// and normals where they are instead of a copy. g gets back the frame before's planes (the
  /// same size from the second frame on, so a loop that gathers into g allocates nothing; its
  /// contents are unspecified). The colour goes straight into `out` (RGB, g's image size),
  /// remodulated and interleaved in one sweep.
  void run_taking(Planes& g, FloatImage& out, SvgfTimes* times = nullptr);
  void reset() { history_ = Planes(); }

 private:
  /// The frame up to the filtered irradiance (returned: one of this object's Planes).
  const Planes& filter(Planes& g, SvgfTimes* times);

  Planes history_, next_;          // irradiance 0-2, moments 3-4, length 5
  Planes previous_;                // the previous frame's inputs (its depth 9 and normals 6-8)
  Planes black_, previous_black_;  // 1 where not demodulated, this frame's and the previous
  Planes copy_;                    // run()'s copy of its input
  Planes x_, acc_, tmp_, demod_, out_;
  Planes aux_;  // variance, luminance, their next pass's, depth gradient x, y
  std::vector<uint8_t> black_rows_;
};

/// The same function written plainly (scalar loops, std::exp): the tests' oracle for Svgf.
struct SvgfReference {
  Planes history;
  Planes run(const Planes& g);
};

/// Dammertz et al. 2010 on demodulated irradiance (scalar): 5 passes, dilation 1..16.
Planes atrous_filter(const Planes& g);

// Shared by both SVGF forms and the a-trous filter.

inline float svgf_luminance(float r, float g, float b) {
  return 0.2126f * r + 0.7152f * g + 0.0722f * b;
}

/// The baselines' demodulation factor per channel (SvgfReference, the a-trous filter; Svgf
/// runs SvgfKernels::demodulate): albedo + 0.01, or 1 where the albedo is
/// (nearly) black. demod gets 3 planes of it, x the demodulated colour; black (if given, W x H
/// floats) 1 where the albedo is black, else 0, and black_rows (if given, H) whether each row
/// holds such a pixel.
void demodulate(const Planes& g, Planes& x, Planes& demod, float* black = nullptr,
                uint8_t* black_rows = nullptr);
/// Whether pixel p of g is not demodulated (black_albedo).
inline bool svgf_black(const Planes& g, size_t p) {
  return black_albedo(g.ch(3)[p], g.ch(4)[p], g.ch(5)[p]);
}
/// out = max(x, 0) * demod.
void remodulate(const Planes& x, const Planes& demod, Planes& out);
/// SVGF's temporal step, shared by both forms (Svgf's first frame; later frames run
/// SvgfKernels::temporal): reprojects `history` (11 planes, as
/// Svgf::next_; empty: none; a tap must match the pixel's depth, normal and black flag) and
/// accumulates x into acc (3 planes), moments m1 m2, history length and variance.
void svgf_temporal(const Planes& g, const Planes& x, const Planes& history, Planes& acc, float* m1,
                   float* m2, float* len, float* var);
/// Central-difference depth gradient of plane 9.
void depth_gradient(const Planes& g, float* gx, float* gy);

}  // namespace kestrel::denoise
