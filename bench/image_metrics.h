// Image-quality measures shared by the evaluation programs (denoiser, upsampler): PSNR and
// SSIM on tone-mapped sRGB (tonemap_aces_srgb), relMSE on linear HDR, side-by-side crops.
#pragma once
#include <string>
#include <vector>

#include "kestrel/io.h"

namespace kestrel::bench {

/// The colour (first 3 channels) through exposure 0, the ACES fit and the sRGB OETF.
std::vector<float> tonemapped(const FloatImage& img);
/// PSNR of two tone-mapped images (peak 1).
double psnr(const std::vector<float>& a, const std::vector<float>& b);
/// SSIM (Wang et al. 2004): 11x11 Gaussian window (sigma 1.5), per channel, averaged.
double ssim(const std::vector<float>& a, const std::vector<float>& b, int w, int h);
/// Relative MSE on linear HDR: mean (o - r)^2 / (r^2 + 0.01).
double relmse(const FloatImage& o, const FloatImage& r);
double median(std::vector<double> v);
/// The same crop of each image side by side, 2x nearest-neighbour, tone-mapped, as PNG.
void write_crop_png(const std::string& path, const std::vector<const FloatImage*>& images, int x0,
                    int y0, int cw, int ch);

}  // namespace kestrel::bench
