// kestrel_denoise_eval: the denoisers on the held-out test clips of
// scripts/denoise/make_dataset.py. Per method and input spp: PSNR and SSIM on tone-mapped
// sRGB (exposure 0 -> ACES fit -> sRGB, tonemap_aces_srgb), relMSE on linear HDR, temporal
// error tErr = mean |(o_t - o_{t-1}) - (r_t - r_{t-1})| (tone-mapped), and ms per 1280x720
// frame (median after warm-up, the machine's threads). Writes a Markdown table, a JSON file
// and side-by-side crops (PNG).
#include <fmt/format.h>
#include <tbb/global_control.h>
#include <CLI/CLI.hpp>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <map>
#include <set>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "common/openmp_env.h"
#include "image_metrics.h"
#include "kestrel/denoise.h"
#include "kestrel/error.h"
#include "kestrel/io.h"
#include "kestrel/render.h"

using namespace kestrel;
using namespace kestrel::bench;
namespace fs = std::filesystem;

namespace {

struct InputFrame {
  FloatImage color, albedo, normal, depth, rough, motion;
  DenoiseInput input() const { return {&color, &albedo, &normal, &depth, &rough, &motion}; }
};

InputFrame load_frame(const fs::path& dir) {
  InputFrame f;
  f.color = read_pfm((dir / "color.pfm").string());
  f.albedo = read_pfm((dir / "albedo.pfm").string());
  f.normal = read_pfm((dir / "normal.pfm").string());
  f.depth = read_pfm((dir / "depth.pfm").string());
  f.rough = read_pfm((dir / "roughness.pfm").string());
  f.motion = read_pfm((dir / "motion.pfm").string());
  return f;
}

struct Scores {
  double psnr = 0, ssim = 0, relmse = 0, terr = 0;
  double psnr0 = 0;   // the first frame alone (no history yet): the single-frame score
  double bright = 0;  // brightest output pixel / brightest reference pixel (max over clips)
  double level = 0;   // the output's mean brightness over the reference's (1: no bias)
  int frames = 0;
};

// The mean of an image's values (its brightness).
double mean_value(const FloatImage& img) {
  double s = 0;
  for (float v : img.pixels) s += double(v);
  return img.pixels.empty() ? 0.0 : s / double(img.pixels.size());
}

float brightest(const FloatImage& img) {
  float m = 0;
  for (float v : img.pixels) m = std::max(m, v);
  return m;
}

// The reference's brightest pixel after a 3x3 median per channel (edges clamped): a
// reference of finite spp keeps fireflies of its own (caustics through mirrors converge
// slowly: a 4096-spp render of the mirror-sphere probe still has pixels 10x its sunlit
// floor), which must not raise the bar the output is held to.
float brightest_robust(const FloatImage& img) {
  float m = 0;
  for (int y = 0; y < img.height; ++y)
    for (int x = 0; x < img.width; ++x)
      for (int c = 0; c < std::min(img.channels, 3); ++c) {
        float v[9];
        int k = 0;
        for (int dy = -1; dy <= 1; ++dy)
          for (int dx = -1; dx <= 1; ++dx)
            v[k++] = img.at(std::clamp(x + dx, 0, img.width - 1),
                            std::clamp(y + dy, 0, img.height - 1))[c];
        std::nth_element(v, v + 4, v + 9);
        m = std::max(m, v[4]);
      }
  return m;
}

// A test clip's family: "test_<family>_<seed>" (families.py) or the clip itself.
std::string family_of(const std::string& clip) {
  std::string f = clip.rfind("test_", 0) == 0 ? clip.substr(5) : clip;
  const size_t us = f.find_last_of('_');
  if (us != std::string::npos && us + 1 < f.size() &&
      f.find_first_not_of("0123456789", us + 1) == std::string::npos)
    f.resize(us);
  return f;
}

struct Method {
  std::string name;
  DenoiserOptions options;
  bool identity = false;  // the noisy input
};

}  // namespace

int main(int argc, char** argv) {
  // It runs rae (oneDNN): OpenMP threads that sleep between its regions (common/openmp_env.h).
  kestrel::cli::passive_openmp_for_onednn(argc, argv, /*always=*/true);
  std::string dataset = std::string(KESTREL_SOURCE_DIR) + "/out/denoise_dataset";
  std::string out_dir = std::string(KESTREL_SOURCE_DIR) + "/docs/denoiser";
  std::string weights;
  int threads = int(std::thread::hardware_concurrency()), repeat = 9;
  bool quick = false, no_rae = false, rae_fp32 = false;
  CLI::App app{"kestrel_denoise_eval: the denoisers on the held-out clips"};
  app.add_option("--dataset", dataset, "The dataset of scripts/denoise/make_dataset.py")
      ->capture_default_str();
  app.add_option("--out", out_dir, "Where eval.md, eval.json and the crops go")
      ->capture_default_str();
  app.add_option("--weights", weights, "Neural weights (default: weights/denoiser.kdw)");
  app.add_option("--threads", threads, "Worker threads")->capture_default_str();
  app.add_option("--repeat", repeat, "Timed frames (median; 0: no timing)")->capture_default_str();
  app.add_flag("--quick", quick, "Three frames per clip, 1 spp only (smoke test)");
  app.add_flag("--no-rae", no_rae, "Leave out the rae quality mode (seconds per 720p frame)");
  app.add_flag("--rae-fp32", rae_fp32,
               "Where the CPU has bf16 convolutions (rae's default there): rae in fp32 as well");
  CLI11_PARSE(app, argc, argv);
  tbb::global_control threads_limit(tbb::global_control::max_allowed_parallelism,
                                    size_t(std::max(threads, 1)));
  try {
    std::vector<Method> methods = {{"input (noisy)", {}, true}};
    DenoiserOptions o;
    o.weights = weights;
    o.method = DenoiseMethod::atrous;
    methods.push_back({"a-trous (Dammertz 2010)", o, false});
    o.method = DenoiseMethod::svgf;
    methods.push_back({"SVGF-like", o, false});
    o.method = DenoiseMethod::neural;
    o.recurrent = false;
    methods.push_back({"neural, frame by frame", o, false});
    o.recurrent = true;
    methods.push_back({"neural (recurrent)", o, false});
    const Denoiser neural(o);
    const size_t params = neural.parameter_count();
    if (neural.uses_bf16()) {  // the default there: bf16 convolutions; f32 beside them
      o.bf16 = false;
      methods.push_back({"neural (recurrent), fp32", o, false});
      o.bf16 = true;
    }
    if (!no_rae) {
      DenoiserOptions r;
      r.method = DenoiseMethod::rae;
      const bool bf16 = Denoiser(r).uses_bf16();
      methods.push_back({bf16 ? "rae (Chaitanya 2017), bf16" : "rae (Chaitanya 2017)", r, false});
      if (bf16 && rae_fp32) {
        r.bf16 = false;
        methods.push_back({"rae (Chaitanya 2017), fp32", r, false});
      }
    }

    // Test clips from the manifest.
    std::ifstream mf(fs::path(dataset) / "manifest.json");
    if (!mf)
      throw Error(ErrorCode::io_error,
                  fmt::format("{}/manifest.json: not found (run scripts/denoise/make_dataset.py)",
                              dataset));
    std::stringstream ss;
    ss << mf.rdbuf();
    const std::string manifest = ss.str();
    std::vector<std::string> clips;
    for (size_t at = manifest.find("\"test_"); at != std::string::npos;
         at = manifest.find("\"test_", at + 1)) {
      const size_t end = manifest.find('"', at + 1);
      const std::string name = manifest.substr(at + 1, end - at - 1);
      if (manifest.compare(end + 1, 1, ":") == 0 &&
          std::find(clips.begin(), clips.end(), name) == clips.end())
        clips.push_back(name);
    }
    if (clips.empty())
      throw Error(ErrorCode::parse_error,
                  fmt::format("{}: no test clips in the manifest", dataset));
    fs::create_directories(out_dir);
    std::map<std::string, std::map<int, Scores>>
        total;  // method -> spp -> scores (summed over clips)
    std::map<std::string, std::map<std::string, Scores>> by_family;  // family -> method (1 spp)
    std::string per_clip;
    const std::vector<int> spps = quick ? std::vector<int>{1} : std::vector<int>{1, 2, 4};
    std::set<std::string> cropped;  // families whose crops are written
    for (const std::string& clip : clips) {
      const fs::path root = fs::path(dataset) / clip;
      int frames = 0;
      while (fs::exists(root / "ref" / "pfm" / fmt::format("frame_{:04d}", frames))) ++frames;
      if (quick) frames = std::min(frames, 3);
      std::vector<FloatImage> refs;
      std::vector<float> ref_bright;
      std::vector<double> ref_level;  // each reference frame's mean brightness
      for (int t = 0; t < frames; ++t) {
        refs.push_back(read_pfm(
            (root / "ref" / "pfm" / fmt::format("frame_{:04d}", t) / "color.pfm").string()));
        ref_bright.push_back(brightest_robust(refs.back()));
        ref_level.push_back(mean_value(refs.back()));
      }
      for (int spp : spps) {
        if (!fs::exists(root / fmt::format("spp{}", spp))) continue;
        std::vector<InputFrame> inputs;
        for (int t = 0; t < frames; ++t)
          inputs.push_back(load_frame(root / fmt::format("spp{}", spp) / "pfm" /
                                      fmt::format("frame_{:04d}", t)));
        std::vector<FloatImage> last;  // per method, the last frame (crops)
        for (const Method& m : methods) {
          std::unique_ptr<Denoiser> d =
              m.identity ? nullptr : std::make_unique<Denoiser>(m.options);
          Scores s;
          std::vector<float> prev_o, prev_r;
          FloatImage out;
          double bright = 0;  // the largest over frames of brightest output / brightest ref
          int level_frames = 0;
          for (int t = 0; t < frames; ++t) {
            out = m.identity ? inputs[size_t(t)].color : d->denoise(inputs[size_t(t)].input());
            const std::vector<float> to = tonemapped(out), tr = tonemapped(refs[size_t(t)]);
            if (ref_bright[size_t(t)] >= 1e-3f)  // a black reference frame has no ratio
              bright = std::max(bright, double(brightest(out)) / double(ref_bright[size_t(t)]));
            if (t == 0) s.psnr0 = psnr(to, tr);
            s.psnr += psnr(to, tr);
            s.ssim += ssim(to, tr, out.width, out.height);
            s.relmse += relmse(out, refs[size_t(t)]);
            if (ref_level[size_t(t)] > 0)
              s.level += mean_value(out) / ref_level[size_t(t)], ++level_frames;
            if (t > 0) {
              double e = 0;
              for (size_t i = 0; i < to.size(); ++i)
                e += std::abs((to[i] - prev_o[i]) - (tr[i] - prev_r[i]));
              s.terr += e / double(to.size());
            }
            prev_o = to, prev_r = tr;
          }
          s.psnr /= frames, s.ssim /= frames, s.relmse /= frames;
          s.level = level_frames > 0 ? s.level / level_frames : 1.0;
          s.terr /= std::max(frames - 1, 1);
          s.frames = frames;
          s.bright = bright;
          per_clip += fmt::format(
              "| {} | {} | {} | {:.2f} | {:.2f} | {:.4f} | {:.4f} | {:.5f} | {:.2f} | {:.3f} |\n",
              clip, spp, m.name, s.psnr0, s.psnr, s.ssim, s.relmse, s.terr, s.bright, s.level);
          fmt::print(
              "{:20s} {} spp  {:26s} PSNR {:6.2f} (frame 0 {:6.2f})  SSIM {:.4f}  relMSE {:.4f}  "
              "tErr {:.5f}  max/ref {:.2f}  mean/ref {:.3f}\n",
              clip, spp, m.name, s.psnr, s.psnr0, s.ssim, s.relmse, s.terr, s.bright, s.level);
          auto add = [&](Scores& t) {
            t.psnr += s.psnr, t.ssim += s.ssim, t.relmse += s.relmse, t.terr += s.terr;
            t.psnr0 += s.psnr0, t.bright = std::max(t.bright, s.bright), t.frames += 1;
            t.level += s.level;
          };
          add(total[m.name][spp]);
          if (spp == 1) add(by_family[family_of(clip)][m.name]);
          last.push_back(out);
        }
        if (spp == 1 && cropped.insert(family_of(clip)).second) {  // a family's first clip
          std::vector<const FloatImage*> imgs;
          for (const FloatImage& f : last) imgs.push_back(&f);
          imgs.push_back(&refs.back());
          const int cw = std::min(128, refs.back().width), ch = std::min(96, refs.back().height);
          write_crop_png((fs::path(out_dir) / (clip + "_crops.png")).string(), imgs,
                         (refs.back().width - cw) / 2, (refs.back().height - ch) / 2, cw, ch);
        }
      }
    }
    // Timing on 1280x720: the first test clip's 1-spp frames tiled.
    const fs::path root = fs::path(dataset) / clips.front() / "spp1" / "pfm";
    std::vector<InputFrame> small;
    for (int t = 0; t < 2; ++t) small.push_back(load_frame(root / fmt::format("frame_{:04d}", t)));
    auto tile = [](const FloatImage& s) {
      FloatImage b(1280, 720, s.channels);
      for (int y = 0; y < 720; ++y)
        for (int x = 0; x < 1280; ++x)
          for (int c = 0; c < s.channels; ++c) b.at(x, y)[c] = s.at(x % s.width, y % s.height)[c];
      return b;
    };
    std::vector<InputFrame> big;
    for (const InputFrame& f : small)
      big.push_back({tile(f.color), tile(f.albedo), tile(f.normal), tile(f.depth), tile(f.rough),
                     tile(f.motion)});
    std::map<std::string, double> ms;
    for (const Method& m : methods) {
      if (m.identity || repeat <= 0) continue;
      Denoiser d(m.options);
      std::vector<double> times;
      FloatImage out;  // reused, as a real-time loop would
      // rae takes seconds per frame: at most 3 timed.
      const int n = m.options.method == DenoiseMethod::rae ? std::min(repeat, 3) : repeat;
      for (int r = 0; r < n + 2; ++r) {
        const auto t0 = std::chrono::steady_clock::now();
        d.denoise(big[size_t(r % 2)].input(), out);
        const double t =
            std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0)
                .count();
        if (r >= 2) times.push_back(t);
      }
      ms[m.name] = median(times);
      fmt::print("{:26s} {:.1f} ms per 1280x720 frame ({} threads, median of {})\n", m.name,
                 ms[m.name], threads, n);
    }
    // Table.
    std::string md = fmt::format(
        "# Denoiser evaluation\n\nWritten by `kestrel_denoise_eval` (bench/denoise_eval.cpp) on "
        "the test clips of `{}`: {}. "
        "Means over clips of per-clip means over frames. PSNR / SSIM on tone-mapped sRGB (ACES "
        "fit, exposure 0), relMSE on "
        "linear HDR ((o-r)^2/(r^2+0.01)), tErr = mean |(o_t - o_t-1) - (r_t - r_t-1)| on "
        "tone-mapped values; ms per "
        "1280x720 frame with {} threads (median of {} after 2 warm-up frames; rae: of at most 3). "
        "Neural (recurrent) parameters: {}.\n\n"
        "PSNR₀ is the first frame alone (no history: the single-frame score); max/ref the "
        "brightest output pixel of a frame over the brightest pixel of that frame's reference "
        "after a 3x3 median (the reference's own fireflies do not count; the largest over "
        "frames and clips; frames whose reference is black, below 1e-3, are left out); mean/ref "
        "the output's mean brightness over the reference's (1: no bias), averaged over frames "
        "and clips.\n\n"
        "| method | spp | PSNR₀ dB | PSNR dB | SSIM | relMSE | tErr | max/ref | mean/ref | "
        "ms @1280x720 |\n|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n",
        fs::path(dataset).filename().string(), fmt::join(clips, ", "), threads, repeat, params);
    std::string json = "{\n  \"clips\": [";
    for (size_t i = 0; i < clips.size(); ++i)
      json += fmt::format("{}\"{}\"", i ? ", " : "", clips[i]);
    json += fmt::format("],\n  \"threads\": {},\n  \"parameters\": {},\n  \"results\": [\n",
                        threads, params);
    bool first = true;
    for (int spp : spps)
      for (const Method& m : methods) {
        auto it = total[m.name].find(spp);
        if (it == total[m.name].end()) continue;
        const Scores& s = it->second;
        const double n = s.frames;
        const std::string t = ms.count(m.name) ? fmt::format("{:.1f}", ms[m.name]) : "";
        md += fmt::format(
            "| {} | {} | {:.2f} | {:.2f} | {:.4f} | {:.4f} | {:.5f} | {:.2f} | {:.3f} | {} |\n",
            m.name, spp, s.psnr0 / n, s.psnr / n, s.ssim / n, s.relmse / n, s.terr / n, s.bright,
            s.level / n, t);
        json += fmt::format(
            "{}    {{\"method\": \"{}\", \"spp\": {}, \"psnr0\": {:.3f}, \"psnr\": {:.3f}, "
            "\"ssim\": {:.4f}, \"relmse\": {:.5f}, \"terr\": {:.5f}, \"max_over_ref\": {:.3f}, "
            "\"mean_over_ref\": {:.4f}, \"ms\": {}}}",
            first ? "" : ",\n", m.name, spp, s.psnr0 / n, s.psnr / n, s.ssim / n, s.relmse / n,
            s.terr / n, s.bright, s.level / n,
            ms.count(m.name) ? fmt::format("{:.2f}", ms[m.name]) : "null");
        first = false;
      }
    json += "\n  ]\n}\n";
    md +=
        "\nPer family (1 spp, means over the family's clips; max/ref the largest):\n\n"
        "| family | method | PSNR₀ dB | PSNR dB | SSIM | relMSE | tErr | max/ref | mean/ref "
        "|\n|---|---|---:|---:|---:|---:|---:|---:|---:|\n";
    for (const auto& [family, per_method] : by_family)
      for (const Method& m : methods) {
        auto it = per_method.find(m.name);
        if (it == per_method.end()) continue;
        const Scores& s = it->second;
        const double n = s.frames;
        md += fmt::format(
            "| {} | {} | {:.2f} | {:.2f} | {:.4f} | {:.4f} | {:.5f} | {:.2f} | {:.3f} |\n", family,
            m.name, s.psnr0 / n, s.psnr / n, s.ssim / n, s.relmse / n, s.terr / n, s.bright,
            s.level / n);
      }
    md +=
        "\nPer clip:\n\n| clip | spp | method | PSNR₀ dB | PSNR dB | SSIM | relMSE | tErr | "
        "max/ref | mean/ref |\n|---|---:|---|---:|---:|---:|---:|---:|---:|---:|\n" +
        per_clip;
    std::string panels;
    for (const Method& m : methods) panels += m.name + "; ";
    md += "\nCrops (last frame, 1 spp; left to right: " + panels +
          "reference): `<clip>_crops.png` (the first clip of each family).\n";
    std::ofstream(fs::path(out_dir) / "eval.md") << md;
    std::ofstream(fs::path(out_dir) / "eval.json") << json;
    fmt::print("wrote {}/eval.md, eval.json and crops\n", out_dir);
  } catch (const std::exception& e) {
    fmt::print(stderr, "kestrel_denoise_eval: error: {}\n", e.what());
    return 1;
  }
  return 0;
}
