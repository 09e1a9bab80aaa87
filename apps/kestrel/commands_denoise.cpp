// `kestrel denoise`: one frame or a sequence, from PFMs (Open Image Denoise's oidnDenoise
// flags) or kestrel's multi-layer EXRs, with the neural denoiser or a baseline.
#include <fmt/format.h>

#include <algorithm>
#include <chrono>
#include <filesystem>
#include <memory>
#include <vector>

#include "commands.h"
#include "core/file_io.h"
#include "kestrel/denoise.h"
#include "kestrel/error.h"
#include "kestrel/io.h"

namespace kestrel::cli {

namespace {

struct DenoiseArgs {
  std::string hdr, alb, nrm, depth, rough, motion, input, out, method = "neural", weights;
  bool sequence = false, no_recurrent = false, quiet = false, fp32 = false;
  int frames = 0, start = 0, bench = 0;
};

}  // namespace

std::string frame_name(const std::string& pattern, int frame) {
  const size_t at = pattern.find('%');
  size_t end = at == std::string::npos ? at : pattern.find('d', at);
  const std::string spec = end == std::string::npos ? "" : pattern.substr(at + 1, end - at - 1);
  const bool ok = at != std::string::npos && end != std::string::npos &&
                  spec.find_first_not_of("0123456789") == std::string::npos && spec.size() <= 2 &&
                  pattern.find('%', end) == std::string::npos;
  if (!ok)
    throw Error(ErrorCode::invalid_argument,
                fmt::format("'{}': a sequence name needs one %d or %0Nd", pattern));
  const int width = spec.empty() ? 0 : std::stoi(spec);
  return pattern.substr(0, at) + fmt::format("{:0{}d}", frame, width) + pattern.substr(end + 1);
}

namespace {

struct Loaded {
  FloatImage color, albedo, normal, depth, rough, motion;
  bool has_albedo = false, has_normal = false, has_depth = false, has_rough = false,
       has_motion = false;
};

Loaded load_inputs(const DenoiseArgs& a, int frame) {
  auto name = [&](const std::string& p) { return a.sequence ? frame_name(p, frame) : p; };
  Loaded l;
  if (!a.input.empty()) {
    const std::string path = name(a.input);
    for (ImageLayer& layer : read_exr(path)) {
      const std::string& n = layer.name;
      if (n == "color" || n.empty())
        l.color = std::move(layer.image);
      else if (n == "albedo")
        l.albedo = std::move(layer.image), l.has_albedo = true;
      else if (n == "normal")
        l.normal = std::move(layer.image), l.has_normal = true;
      else if (n == "depth")
        l.depth = std::move(layer.image), l.has_depth = true;
      else if (n == "roughness")
        l.rough = std::move(layer.image), l.has_rough = true;
      else if (n == "motion")
        l.motion = std::move(layer.image), l.has_motion = true;
    }
    if (l.color.width == 0)
      throw Error(ErrorCode::parse_error, fmt::format("{}: no colour (R,G,B) layer", path));
    return l;
  }
  l.color = read_float_image(name(a.hdr));
  auto opt = [&](const std::string& p, FloatImage& img, bool& has) {
    if (!p.empty()) img = read_float_image(name(p)), has = true;
  };
  opt(a.alb, l.albedo, l.has_albedo);
  opt(a.nrm, l.normal, l.has_normal);
  opt(a.depth, l.depth, l.has_depth);
  opt(a.rough, l.rough, l.has_rough);
  opt(a.motion, l.motion, l.has_motion);
  return l;
}

}  // namespace

void write_image(const std::string& path, const FloatImage& img) {
  make_parent_directories(path);
  const std::string ext = lower_extension(path);
  if (ext == ".exr") {
    const ImageLayer layer{"", {"R", "G", "B"}, img};
    write_exr(path, std::span<const ImageLayer>(&layer, 1));
  } else if (ext == ".pfm") {
    write_pfm(path, img);
  } else {
    throw Error(ErrorCode::invalid_argument, fmt::format("{}: output must be .pfm or .exr", path));
  }
}

namespace {

void run_denoise(const DenoiseArgs& a) {
  if (a.hdr.empty() == a.input.empty())
    throw Error(ErrorCode::invalid_argument,
                "denoise: give --hdr color.pfm (with --alb/--nrm/...) or --input frame.exr");
  if (a.out.empty())
    throw Error(ErrorCode::invalid_argument, "denoise: -o out.pfm|out.exr is required");
  const auto method = denoise_method_from_name(a.method);
  if (!method)
    throw Error(
        ErrorCode::invalid_argument,
        fmt::format("denoise: unknown --method '{}' (neural, svgf, atrous, rae)", a.method));
  if (a.sequence && a.frames <= 0)
    throw Error(ErrorCode::invalid_argument, "denoise: --sequence needs --frames N");
  DenoiserOptions o;
  o.method = *method;
  o.weights = a.weights;
  o.recurrent = !a.no_recurrent;
  o.bf16 = !a.fp32;
  Denoiser denoiser(o);
  const int count = a.sequence ? a.frames : 1;
  for (int i = 0; i < count; ++i) {
    const int frame = a.start + i;
    const Loaded l = load_inputs(a, frame);
    DenoiseInput in;
    in.color = &l.color;
    in.albedo = l.has_albedo ? &l.albedo : nullptr;
    in.normal = l.has_normal ? &l.normal : nullptr;
    in.depth = l.has_depth ? &l.depth : nullptr;
    in.roughness = l.has_rough ? &l.rough : nullptr;
    in.motion = l.has_motion ? &l.motion : nullptr;
    auto t0 = std::chrono::steady_clock::now();
    const FloatImage out = denoiser.denoise(in);
    double ms =
        std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
    if (a.bench > 0) {  // as oidnDenoise --bench: the same frame again (state carried), median
      std::vector<double> times;
      FloatImage kept;  // as a frame loop: the output's storage reused
      for (int r = 0; r < a.bench; ++r) {
        t0 = std::chrono::steady_clock::now();
        denoiser.denoise(in, kept);
        times.push_back(
            std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0)
                .count());
      }
      std::sort(times.begin(), times.end());
      ms = times[times.size() / 2];
      fmt::print("bench    {} runs after the first: median {:.1f} ms, min {:.1f} ms\n", a.bench, ms,
                 times.front());
    }
    const std::string path = a.sequence ? frame_name(a.out, frame) : a.out;
    write_image(path, out);
    if (!a.quiet)
      fmt::print("denoised {}x{} ({}{}) in {:.1f} ms -> {}\n", out.width, out.height, a.method,
                 denoiser.uses_bf16() ? ", bf16" : "", ms, path);
  }
}

}  // namespace

Action add_denoise_command(CLI::App& cmd) {
  auto a = std::make_shared<DenoiseArgs>();
  cmd.add_option("--hdr,--color", a->hdr, "Noisy colour, linear HDR (.pfm .exr .hdr)");
  cmd.add_option("--alb,--albedo", a->alb, "Albedo AOV");
  cmd.add_option("--nrm,--normal", a->nrm, "World-space normal AOV");
  cmd.add_option("--depth", a->depth, "Depth AOV");
  cmd.add_option("--rough,--roughness", a->rough, "Roughness AOV");
  cmd.add_option("--motion", a->motion, "Motion vectors, pixels (p + motion = previous position)");
  cmd.add_option("-i,--input", a->input,
                 "kestrel's multi-layer EXR (every AOV) instead of separate files");
  cmd.add_option("-o,--output", a->out, "Output .pfm or .exr")->required();
  cmd.add_option("--method", a->method,
                 "neural | svgf | atrous | rae (the recurrent autoencoder, Chaitanya et al. 2017: "
                 "seconds per 720p frame, for final frames)")
      ->capture_default_str();
  cmd.add_option("--weights", a->weights,
                 "Weights file of neural or rae (default: weights/denoiser.kdw, denoiser_rae.kdw)");
  cmd.add_flag("--sequence", a->sequence,
               "File names are printf patterns (%04d); recurrent state carries over");
  cmd.add_option("--frames", a->frames, "Frames of the sequence");
  cmd.add_option("--start", a->start, "First frame number")->capture_default_str();
  cmd.add_flag("--no-recurrent", a->no_recurrent,
               "Neural: each frame alone (no warped previous output)");
  cmd.add_flag(
      "--fp32", a->fp32,
      "neural, rae: fp32 convolutions even where the CPU has bf16 ones (the default there)");
  cmd.add_flag("--quiet", a->quiet, "Print nothing");
  cmd.add_option("--bench", a->bench,
                 "Denoise each frame this many more times and print the median time");
  return [a] { run_denoise(*a); };
}

}  // namespace kestrel::cli
