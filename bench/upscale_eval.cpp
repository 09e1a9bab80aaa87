// kestrel_upscale_eval: the upsamplers on the held-out test clips of
// scripts/upscale/make_dataset.py, at factors 2 and 4. Per method: PSNR and SSIM on tone-mapped
// sRGB against the full-resolution reference, temporal error tErr = mean |(o_t - o_{t-1}) -
// (r_t - r_{t-1})| (tone-mapped), and ms per 1280x720 output frame (median after warm-up, the
// machine's threads). Writes a Markdown table, a JSON file and side-by-side crops (PNG).
#include <fmt/format.h>
#include <tbb/global_control.h>
#include <CLI/CLI.hpp>

#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
#include <string>
#include <thread>
#include <vector>

#include "common/openmp_env.h"
#include "image_metrics.h"
#include "kestrel/error.h"
#include "kestrel/io.h"
#include "kestrel/render.h"
#include "kestrel/upscale.h"

using namespace kestrel;
using namespace kestrel::bench;
namespace fs = std::filesystem;

namespace {

struct LowFrame {
  FloatImage color, depth, motion;
  float jx = 0.5f, jy = 0.5f;
  UpscaleInput input() const { return {&color, &depth, &motion, jx, jy}; }
};

LowFrame load_low(const fs::path& dir, int frame) {
  LowFrame f;
  f.color = read_pfm((dir / "color.pfm").string());
  const FloatImage d = read_pfm((dir / "depth.pfm").string());
  f.depth = FloatImage(d.width, d.height, 1);
  for (size_t p = 0; p < f.depth.pixels.size(); ++p)
    f.depth.pixels[p] = d.pixels[p * size_t(d.channels)];
  f.motion = read_pfm((dir / "motion.pfm").string());
  frame_jitter(uint32_t(frame), f.jx, f.jy);
  return f;
}

struct Scores {
  double psnr = 0, ssim = 0, terr = 0;
  int n = 0;
};

const UpscaleMethod kMethods[] = {UpscaleMethod::bilinear, UpscaleMethod::bicubic,
                                  UpscaleMethod::taau,     UpscaleMethod::neural,
                                  UpscaleMethod::nsrr_rt,  UpscaleMethod::nsrr};

const char* label(UpscaleMethod m) {
  switch (m) {
    case UpscaleMethod::bilinear:
      return "bilinear";
    case UpscaleMethod::bicubic:
      return "bicubic (Catmull-Rom)";
    case UpscaleMethod::taau:
      return "TAAU-like";
    case UpscaleMethod::nsrr:
      return "nsrr (Xiao et al.)";
    case UpscaleMethod::nsrr_rt:
      return "nsrr-rt (real-time)";
    default:
      return "neural (learned TAAU)";
  }
}

// The inputs an upsampler is fed: the clean point-sampled frames (x<f>/), and the same frames
// at 1 spp through the denoiser (x<f>_dn/, make_dataset.py --denoised) where the clip has them.
struct Variant {
  const char* name;
  const char* suffix;
};
const Variant kVariants[] = {{"clean", ""}, {"denoised 1 spp", "_dn"}};

}  // namespace

int main(int argc, char** argv) {
  // It runs nsrr (oneDNN): OpenMP threads that sleep between its regions (common/openmp_env.h).
  kestrel::cli::passive_openmp_for_onednn(argc, argv, /*always=*/true);
  std::string dataset = std::string(KESTREL_SOURCE_DIR) + "/out/upscale_families";
  std::string out_dir = std::string(KESTREL_SOURCE_DIR) + "/docs/upscaler";
  std::string weights, rt_weights, nsrr_weights;
  std::vector<std::string> only;
  int threads = int(std::thread::hardware_concurrency()), repeat = 9;
  bool quick = false, fp32 = false;
  CLI::App app{"kestrel_upscale_eval: the upsamplers on the held-out clips"};
  app.add_option("--dataset", dataset, "The dataset of scripts/upscale/make_dataset.py")
      ->capture_default_str();
  app.add_option("--out", out_dir, "Where eval.md, eval.json and the crops go")
      ->capture_default_str();
  app.add_option("--weights", weights, "Learned TAAU weights (default: weights/upscaler.kdw)");
  app.add_option("--nsrr-weights", nsrr_weights,
                 "nsrr weights (default: weights/upscaler_nsrr.kdw)");
  app.add_option("--nsrr-rt-weights", rt_weights,
                 "nsrr-rt weights (default: weights/upscaler_nsrr_rt.kdw)");
  app.add_option("--methods", only,
                 fmt::format("Only these methods, comma-separated (of {})", upscale_method_list()))
      ->delimiter(',');
  app.add_option("--threads", threads, "Worker threads")->capture_default_str();
  app.add_option("--repeat", repeat, "Timed frames (median)")->capture_default_str();
  app.add_flag("--quick", quick, "Three frames per clip (smoke test)");
  app.add_flag("--fp32", fp32,
               "Every network's convolutions in f32, even where the CPU has bf16 ones (the "
               "default there)");
  CLI11_PARSE(app, argc, argv);
  tbb::global_control threads_limit(tbb::global_control::max_allowed_parallelism,
                                    size_t(std::max(threads, 1)));
  try {
    std::ifstream mf(fs::path(dataset) / "manifest.json");
    if (!mf)
      throw Error(ErrorCode::io_error,
                  fmt::format("{}/manifest.json: not found (run scripts/upscale/make_dataset.py)",
                              dataset));
    const nlohmann::json manifest = nlohmann::json::parse(mf);
    std::vector<std::string> clips;
    std::map<std::string, std::string> family;  // clip -> its family (shared scenes: the clip)
    for (const auto& [name, c] : manifest.at("clips").items())
      if (c.at("split") == "test") {
        clips.push_back(name);
        const std::string fam = c.value("family", std::string());
        family[name] = fam.empty() ? name : fam;
      }
    if (clips.empty())
      throw Error(ErrorCode::parse_error,
                  fmt::format("{}: no test clips in the manifest", dataset));
    fs::create_directories(out_dir);
    auto options = [&](UpscaleMethod m, int f) {
      UpscalerOptions o;
      o.method = m, o.factor = f, o.bf16 = !fp32;
      if (m == UpscaleMethod::neural) o.weights = weights;
      if (m == UpscaleMethod::nsrr) o.weights = nsrr_weights;
      if (m == UpscaleMethod::nsrr_rt) o.weights = rt_weights;
      return o;
    };
    std::vector<UpscaleMethod> wanted(std::begin(kMethods), std::end(kMethods));
    if (!only.empty()) wanted.clear();
    for (const std::string& name : only) {
      const auto m = upscale_method_from_name(name);
      if (!m)
        throw Error(
            ErrorCode::invalid_argument,
            fmt::format("--methods: no method '{}' (methods: {})", name, upscale_method_list()));
      wanted.push_back(*m);
    }
    // The methods whose weights load (a missing network is reported, not fatal).
    std::vector<UpscaleMethod> methods;
    std::map<UpscaleMethod, size_t> params;
    bool bf16 = false;  // whether a network's convolutions run in bf16 (this CPU, --fp32)
    for (UpscaleMethod m : wanted) try {
        const Upscaler up(options(m, 2));
        params[m] = up.parameter_count();
        bf16 |= up.uses_bf16();
        methods.push_back(m);
      } catch (const Error& e) {
        fmt::print("skipping {}: {}\n", label(m), e.what());
      }
    // scores[variant][f][family][method], summed over the family's clips.
    std::map<std::string, std::map<int, std::map<std::string, std::map<UpscaleMethod, Scores>>>>
        scores;
    std::map<std::string, std::map<int, std::map<UpscaleMethod, Scores>>> total;
    nlohmann::json json_clips = nlohmann::json::array();
    std::string per_clip;
    for (const std::string& clip : clips) {
      const fs::path root = fs::path(dataset) / clip;
      int frames = 0;
      while (fs::exists(root / "full" / "pfm" / fmt::format("frame_{:04d}", frames))) ++frames;
      if (quick) frames = std::min(frames, 3);
      std::vector<FloatImage> refs;
      std::vector<std::vector<float>> refs_tm;
      float ref_max = 0;
      for (int t = 0; t < frames; ++t) {
        refs.push_back(read_pfm(
            (root / "full" / "pfm" / fmt::format("frame_{:04d}", t) / "color.pfm").string()));
        refs_tm.push_back(tonemapped(refs.back()));
        for (float v : refs.back().pixels) ref_max = std::max(ref_max, v);
      }
      for (const Variant& var : kVariants)
        for (int f : {2, 4}) {
          const fs::path low_dir = root / fmt::format("x{}{}", f, var.suffix);
          if (!fs::exists(low_dir)) continue;
          std::vector<LowFrame> low;
          for (int t = 0; t < frames; ++t)
            low.push_back(load_low(low_dir / "pfm" / fmt::format("frame_{:04d}", t), t));
          std::vector<FloatImage> last;
          for (UpscaleMethod m : methods) {
            Upscaler up(options(m, f));
            Scores s;
            std::vector<float> prev;
            FloatImage out;
            float out_max = 0;
            for (int t = 0; t < frames; ++t) {
              up.upscale(low[size_t(t)].input(), out);
              if (out.width != refs[size_t(t)].width || out.height != refs[size_t(t)].height)
                throw Error(
                    ErrorCode::invalid_argument,
                    fmt::format("{}: x{} frames do not upsample to the reference size", clip, f));
              for (float v : out.pixels) out_max = std::max(out_max, v);
              const std::vector<float> to = tonemapped(out);
              const std::vector<float>& tr = refs_tm[size_t(t)];
              s.psnr += psnr(to, tr);
              s.ssim += ssim(to, tr, out.width, out.height);
              if (t > 0) {
                double e = 0;
                const std::vector<float>& pr = refs_tm[size_t(t - 1)];
                for (size_t i = 0; i < to.size(); ++i)
                  e += std::abs((to[i] - prev[i]) - (tr[i] - pr[i]));
                s.terr += e / double(to.size());
              }
              prev = to;
            }
            s.psnr /= frames, s.ssim /= frames, s.terr /= std::max(frames - 1, 1), s.n = 1;
            const double bright = out_max / std::max(ref_max, 1e-6f);
            per_clip += fmt::format("| {} | {} | x{} | {} | {:.2f} | {:.4f} | {:.5f} | {:.2f} |\n",
                                    clip, var.name, f, label(m), s.psnr, s.ssim, s.terr, bright);
            fmt::print(
                "{:24s} {:14s} x{}  {:24s} PSNR {:6.2f}  SSIM {:.4f}  tErr {:.5f}  max/ref "
                "{:.2f}\n",
                clip, var.name, f, label(m), s.psnr, s.ssim, s.terr, bright);
            json_clips.push_back({{"clip", clip},
                                  {"family", family[clip]},
                                  {"input", var.name},
                                  {"factor", f},
                                  {"method", upscale_method_name(m)},
                                  {"psnr", s.psnr},
                                  {"ssim", s.ssim},
                                  {"terr", s.terr},
                                  {"max_over_ref_max", bright},
                                  {"frames", frames}});
            for (Scores* tt : {&scores[var.name][f][family[clip]][m], &total[var.name][f][m]})
              tt->psnr += s.psnr, tt->ssim += s.ssim, tt->terr += s.terr, tt->n += 1;
            last.push_back(out);
          }
          std::vector<const FloatImage*> imgs;
          for (const FloatImage& o : last) imgs.push_back(&o);
          imgs.push_back(&refs.back());
          const int cw = std::min(96, refs.back().width), ch = std::min(72, refs.back().height);
          write_crop_png(
              (fs::path(out_dir) / fmt::format("{}{}_x{}_crops.png", clip, var.suffix, f)).string(),
              imgs, (refs.back().width - cw) / 2, (refs.back().height - ch) / 2, cw, ch);
        }
    }
    // Timing per 1280x720 output: the first clip's low-resolution frames tiled to 640x360 /
    // 320x180.
    std::map<int, std::map<UpscaleMethod, double>> ms;
    std::map<int, std::map<UpscaleMethod, std::map<std::string, double>>> stages;
    for (int f : {2, 4}) {
      const int lw = 1280 / f, lh = 720 / f;
      auto tile = [&](const FloatImage& s) {
        FloatImage b(lw, lh, s.channels);
        for (int y = 0; y < lh; ++y)
          for (int x = 0; x < lw; ++x)
            for (int c = 0; c < s.channels; ++c) b.at(x, y)[c] = s.at(x % s.width, y % s.height)[c];
        return b;
      };
      std::vector<LowFrame> big;
      for (int t = 0; t < 2; ++t) {
        LowFrame s = load_low(fs::path(dataset) / clips.front() / fmt::format("x{}", f) / "pfm" /
                                  fmt::format("frame_{:04d}", t),
                              t);
        big.push_back({tile(s.color), tile(s.depth), tile(s.motion), s.jx, s.jy});
      }
      for (UpscaleMethod m : methods) {
        Upscaler up(options(m, f));
        std::vector<double> times, feat, net, rec, hist;
        FloatImage out;
        const int timed = m == UpscaleMethod::nsrr ? std::min(repeat, 3) : repeat;
        for (int r = 0; r < timed + 2; ++r) {
          const auto t0 = std::chrono::steady_clock::now();
          up.upscale(big[size_t(r % 2)].input(), out);
          const double t =
              std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0)
                  .count();
          if (r >= 2) {
            times.push_back(t);
            const Upscaler::Times st = up.last_times();
            feat.push_back(st.features), net.push_back(st.network), rec.push_back(st.reconstruct),
                hist.push_back(st.history);
          }
        }
        ms[f][m] = median(times);
        stages[f][m] = {{"features", median(feat)},
                        {"network", median(net)},
                        {"reconstruct", median(rec)},
                        {"history", median(hist)}};
        fmt::print("x{} {:24s} {:.1f} ms per 1280x720 output ({} threads, median of {})\n", f,
                   label(m), ms[f][m], threads, timed);
      }
    }
    std::string md = fmt::format(
        "# Upsampler evaluation\n\nWritten by `kestrel_upscale_eval` (bench/upscale_eval.cpp) on "
        "the held-out test clips of `{}`: {}. Held-out clips are of families never seen in "
        "training (and the shared scenes). Inputs: the clips rendered at 1/2 and 1/4 of the "
        "reference resolution at kestrel's per-frame Halton jitter, either clean (point-sampled, "
        "many samples: `--fixed-jitter`) or at 1 spp through the neural denoiser (what the "
        "real-time loop feeds the upsampler). References: the full resolution, many samples per "
        "pixel. Means over clips of per-clip means over every frame (the first frame has no "
        "history). PSNR / SSIM on tone-mapped sRGB (ACES fit, exposure 0); tErr = mean |(o_t - "
        "o_(t-1)) - (r_t - r_(t-1))|, tone-mapped; max/ref: the brightest output value over the "
        "brightest reference value. Time: ms per 1280x720 output frame (tiled test frames), {} "
        "threads, median of {} after 2 warm-up frames (nsrr: of 3). Parameters:",
        fs::relative(dataset, KESTREL_SOURCE_DIR).string(), fmt::join(clips, ", "), threads,
        repeat);
    for (UpscaleMethod m : methods)
      if (params[m]) md += fmt::format(" {} {};", label(m), params[m]);
    md += bf16 ? " convolutions in bf16 (the default on this CPU; `--fp32` for f32).\n\n"
               : " convolutions in f32.\n\n";
    nlohmann::json json_total = nlohmann::json::array();
    for (const Variant& var : kVariants)
      for (int f : {2, 4}) {
        if (!total[var.name].count(f)) continue;
        md += fmt::format("## {} inputs, factor {}x{}\n\n| method | PSNR dB | SSIM | tErr |",
                          var.name, f, f);
        if (var.suffix[0] == 0) md += fmt::format(" ms ({}x{} -> 1280x720) |", 1280 / f, 720 / f);
        md += var.suffix[0] == 0 ? "\n|---|---:|---:|---:|---:|\n" : "\n|---|---:|---:|---:|\n";
        for (UpscaleMethod m : methods) {
          const Scores& s = total[var.name][f][m];
          md += fmt::format("| {} | {:.2f} | {:.4f} | {:.5f} |", label(m), s.psnr / s.n,
                            s.ssim / s.n, s.terr / s.n);
          if (var.suffix[0] == 0) md += fmt::format(" {:.1f} |", ms[f][m]);
          md += "\n";
          json_total.push_back({{"input", var.name},
                                {"factor", f},
                                {"method", upscale_method_name(m)},
                                {"psnr", s.psnr / s.n},
                                {"ssim", s.ssim / s.n},
                                {"terr", s.terr / s.n},
                                {"ms_1280x720", ms[f][m]}});
        }
        // Per family: PSNR of each method, and the learned ones against TAAU-like.
        md += "\nPSNR dB per family";
        for (UpscaleMethod m : methods) md += fmt::format(" | {}", label(m));
        md += " | neural - TAAU | nsrr-rt - TAAU | nsrr - TAAU |\n|---";
        for (size_t i = 0; i < methods.size() + 3; ++i) md += "|---:";
        md += "|\n";
        for (const auto& [fam, by_method] : scores[var.name][f]) {
          md += "| " + fam;
          auto mean = [&](UpscaleMethod m) {
            const auto it = by_method.find(m);
            return it == by_method.end() ? NAN : it->second.psnr / it->second.n;
          };
          for (UpscaleMethod m : methods) md += fmt::format(" | {:.2f}", mean(m));
          const double taau = mean(UpscaleMethod::taau);
          for (UpscaleMethod m :
               {UpscaleMethod::neural, UpscaleMethod::nsrr_rt, UpscaleMethod::nsrr}) {
            const double gain = mean(m) - taau;
            md += std::isnan(gain) ? std::string(" | -")  // a method not run (--methods)
                                   : fmt::format(" | {:+.2f}", gain);
          }
          md += " |\n";
        }
        if (var.suffix[0] == 0)
          for (UpscaleMethod m :
               {UpscaleMethod::neural, UpscaleMethod::nsrr_rt, UpscaleMethod::nsrr})
            if (stages[f].count(m))
              md += fmt::format(
                  "\n{} stages (ms): features {:.1f}, networks {:.1f}, output {:.1f}{}.\n",
                  label(m), stages[f][m]["features"], stages[f][m]["network"],
                  stages[f][m]["reconstruct"],
                  stages[f][m]["history"] > 0
                      ? fmt::format(", the learned TAAU beside it {:.1f}", stages[f][m]["history"])
                      : "");
        md += "\n";
      }
    md +=
        "## Per clip\n\n| clip | input | factor | method | PSNR dB | SSIM | tErr | max/ref "
        "|\n|---|---|---|---|---:|---:|---:|---:|\n" +
        per_clip;
    md +=
        "\nCrops (`<clip>[_dn]_x<f>_crops.png`, last frame, centre, 2x nearest): each method in "
        "the order of the tables, then the reference.\n";
    std::ofstream((fs::path(out_dir) / "eval.md").string()) << md;
    nlohmann::json jp;
    for (UpscaleMethod m : methods) jp[upscale_method_name(m)] = params[m];
    std::ofstream((fs::path(out_dir) / "eval.json").string()) << nlohmann::json{
        {"threads", threads},
        {"repeat", repeat},
        {"parameters", jp},
        {"means", json_total},
        {"clips", json_clips}}.dump(1);
    fmt::print("wrote {}/eval.md, eval.json and crops\n", out_dir);
  } catch (const Error& e) {
    fmt::print(stderr, "kestrel_upscale_eval: {}\n", e.what());
    return 1;
  }
  return 0;
}
