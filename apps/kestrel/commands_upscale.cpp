// `kestrel upscale`: a jittered low-resolution sequence (kestrel's multi-layer EXRs, or PFMs)
// to factor x its resolution, with the neural upsampler or a baseline.
#include <fmt/format.h>

#include <algorithm>
#include <chrono>
#include <filesystem>
#include <memory>
#include <vector>

#include "commands.h"
#include "kestrel/error.h"
#include "kestrel/io.h"
#include "kestrel/render.h"
#include "kestrel/upscale.h"

namespace kestrel::cli {

namespace {

struct UpscaleArgs {
  std::string input, pattern, color, depth, motion, out, method = "neural", weights,
                                                         jitter = "halton";
  bool sequence = false, quiet = false, fp32 = false;
  int frames = 0, start = 0, factor = 2, bench = 0;
};

struct Loaded {
  FloatImage color, depth, motion;
  bool has_depth = false, has_motion = false;
};

Loaded load(const UpscaleArgs& a, int frame) {
  auto name = [&](const std::string& p) { return a.sequence ? frame_name(p, frame) : p; };
  Loaded l;
  if (!a.input.empty()) {
    const std::string path = name(a.input);
    for (ImageLayer& layer : read_exr(path)) {
      if (layer.name == "color" || layer.name.empty())
        l.color = std::move(layer.image);
      else if (layer.name == "depth")
        l.depth = std::move(layer.image), l.has_depth = true;
      else if (layer.name == "motion")
        l.motion = std::move(layer.image), l.has_motion = true;
    }
    if (l.color.width == 0)
      throw Error(ErrorCode::parse_error, fmt::format("{}: no colour (R,G,B) layer", path));
    return l;
  }
  l.color = read_float_image(name(a.color));
  if (!a.depth.empty()) l.depth = read_float_image(name(a.depth)), l.has_depth = true;
  if (!a.motion.empty()) l.motion = read_float_image(name(a.motion)), l.has_motion = true;
  if (l.has_depth &&
      l.depth.channels == 3) {  // PFMs of a single channel read as 1; guard 3-channel ones
    FloatImage d(l.depth.width, l.depth.height, 1);
    for (size_t p = 0; p < d.pixels.size(); ++p) d.pixels[p] = l.depth.pixels[3 * p];
    l.depth = std::move(d);
  }
  return l;
}

// halton: kestrel's 1-spp sequence for the frame number; center; or "X,Y".
void jitter_of(const std::string& spec, int frame, float& jx, float& jy) {
  if (spec == "halton") return frame_jitter(uint32_t(std::max(frame, 0)), jx, jy);
  if (spec == "center") {
    jx = jy = 0.5f;
    return;
  }
  char* end = nullptr;
  jx = std::strtof(spec.c_str(), &end);
  if (end && *end == ',') {
    const char* second = end + 1;
    jy = std::strtof(second, &end);
    if (end != second && *end == '\0' && std::isfinite(jx) && std::isfinite(jy)) return;
  }
  throw Error(ErrorCode::invalid_argument,
              fmt::format("--jitter '{}': expected halton, center or X,Y", spec));
}

// Frames of a sequence when --frames is not given: consecutive files from --start.
int count_frames(const UpscaleArgs& a) {
  const std::string& pattern = a.input.empty() ? a.color : a.input;
  int n = 0;
  while (std::filesystem::exists(frame_name(pattern, a.start + n))) ++n;
  if (n == 0)
    throw Error(ErrorCode::io_error, fmt::format("{}: no such file", frame_name(pattern, a.start)));
  return n;
}

void run_upscale(const UpscaleArgs& a) {
  if (a.input.empty() == a.color.empty())
    throw Error(ErrorCode::invalid_argument,
                "upscale: give --sequence in_%04d.exr or -i frame.exr (kestrel frames), or --color "
                "c.pfm [--depth --motion]");
  const auto method = upscale_method_from_name(a.method);
  if (!method)
    throw Error(ErrorCode::invalid_argument, fmt::format("upscale: unknown --method '{}' ({})",
                                                         a.method, upscale_method_list()));
  UpscalerOptions o;
  o.method = *method, o.factor = a.factor, o.weights = a.weights, o.bf16 = !a.fp32;
  Upscaler up(o);
  const int count = a.sequence ? (a.frames > 0 ? a.frames : count_frames(a)) : 1;
  FloatImage out;
  std::vector<double> ms, stage[4];
  for (int i = 0; i < count; ++i) {
    const int frame = a.start + i;
    const Loaded l = load(a, frame);
    UpscaleInput in;
    in.color = &l.color;
    in.depth = l.has_depth ? &l.depth : nullptr;
    in.motion = l.has_motion ? &l.motion : nullptr;
    jitter_of(a.jitter, frame, in.jitter_x, in.jitter_y);
    for (int r = 0; r <= a.bench; ++r) {  // --bench: the frame again (history carried on)
      const auto t0 = std::chrono::steady_clock::now();
      up.upscale(in, out);
      if (r > 0 || a.bench == 0) {
        ms.push_back(
            std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0)
                .count());
        const Upscaler::Times t = up.last_times();
        stage[0].push_back(t.features), stage[1].push_back(t.network),
            stage[2].push_back(t.reconstruct), stage[3].push_back(t.history);
      }
    }
    const std::string path = a.sequence ? frame_name(a.out, frame) : a.out;
    write_image(path, out);
    if (!a.quiet)
      fmt::print("upscaled {}x{} -> {}x{} ({}, jitter {:.3f},{:.3f}) in {:.1f} ms -> {}\n",
                 l.color.width, l.color.height, out.width, out.height, a.method, in.jitter_x,
                 in.jitter_y, ms.back(), path);
  }
  const auto median = [](std::vector<double>& v) {
    std::sort(v.begin(), v.end());
    return v[v.size() / 2];
  };
  fmt::print(
      "upscale  {} frames, {}{}: median {:.1f} ms per {}x{} output frame (features {:.1f}, "
      "network {:.1f}, reconstruction {:.1f}{})\n",
      count, a.method, up.uses_bf16() ? " (bf16)" : "", median(ms), out.width, out.height,
      median(stage[0]), median(stage[1]), median(stage[2]),
      stage[3].back() > 0 ? fmt::format(", the learned TAAU beside it {:.1f}", median(stage[3]))
                          : "");
}

}  // namespace

Action add_upscale_command(CLI::App& cmd) {
  auto a = std::make_shared<UpscaleArgs>();
  cmd.add_option("-i,--input", a->input,
                 "kestrel's multi-layer EXR frame (colour, depth, motion layers)");
  cmd.add_option("--color,--hdr", a->color, "Or: low-resolution colour, linear (.pfm .exr .hdr)");
  cmd.add_option("--depth", a->depth, "With --color: depth");
  cmd.add_option(
      "--motion", a->motion,
      "With --color: motion vectors, low-resolution pixels (p + motion = previous position)");
  cmd.add_option("-o,--output", a->out, "Output .exr or .pfm (a %04d pattern with --sequence)")
      ->required();
  cmd.add_option("--factor", a->factor, "2 or 4")->capture_default_str();
  cmd.add_option(
         "--method", a->method,
         upscale_method_list(" | ") +
             " (nsrr: Xiao et al. 2020's neural supersampling, far from real time; nsrr-rt: its "
             "real-time member; both blend in the output of neural, run beside them)")
      ->capture_default_str();
  cmd.add_option("--weights", a->weights,
                 "Weights file (default: weights/upscaler.kdw, upscaler_nsrr.kdw, "
                 "upscaler_nsrr_rt.kdw; nsrr's history runs weights/upscaler.kdw)");
  cmd.add_option("--jitter", a->jitter,
                 "Sample position in each input pixel: halton (kestrel's 1-spp sequence by frame "
                 "number), center, or X,Y")
      ->capture_default_str();
  cmd.add_option(
      "--sequence", a->pattern,
      "A sequence of kestrel EXR frames, a printf pattern (in_%04d.exr); -o is then a pattern too");
  cmd.add_option("--frames", a->frames,
                 "Frames of the sequence (default: every consecutive file from --start)");
  cmd.add_option("--start", a->start, "First frame number")->capture_default_str();
  cmd.add_option("--bench", a->bench,
                 "Upscale each frame this many more times; the median counts those");
  cmd.add_flag(
      "--fp32", a->fp32,
      "neural, nsrr, nsrr-rt: fp32 convolutions even where the CPU has bf16 ones (the default "
      "there)");
  cmd.add_flag("--quiet", a->quiet, "Only the summary line");
  return [a] {
    if (!a->pattern.empty()) {
      if (!a->input.empty())
        throw Error(ErrorCode::invalid_argument, "upscale: give -i or --sequence, not both");
      a->input = a->pattern, a->sequence = true;
    }
    run_upscale(*a);
  };
}

}  // namespace kestrel::cli
