// The `kestrel` binary end to end: help, errors and exit codes, and a rays -> trace -> hits
// round trip checked against the library.
#include <fmt/format.h>
#include <gtest/gtest.h>

#include <sys/wait.h>
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>

#include "kestrel/kestrel.h"
#include "kestrel/render.h"
#include "support/oracles.h"

namespace kestrel {
namespace {

struct CliRun {
  int status;
  std::string out;  // stdout and stderr
};

CliRun run(const std::string& args, const std::string& env = "") {
  const std::string cmd = env + (env.empty() ? "" : " ") + KESTREL_CLI + " " + args + " 2>&1";
  CliRun r{0, ""};
  FILE* p = popen(cmd.c_str(), "r");
  std::array<char, 4096> buf;
  while (size_t n = fread(buf.data(), 1, buf.size(), p)) r.out.append(buf.data(), n);
  const int st = pclose(p);
  r.status = WIFEXITED(st) ? WEXITSTATUS(st) : -1;
  return r;
}

TEST(Cli, HelpForEveryCommand) {
  for (const char* c : {"", "bvh", "trace", "rays", "preview", "render", "render-sequence",
                        "denoise", "upscale", "run", "view"}) {
    const CliRun r = run(std::string(c) + " --help");
    EXPECT_EQ(r.status, 0) << c << ": " << r.out;
    EXPECT_NE(r.out.find("Usage"), std::string::npos) << c;
  }
}

TEST(Cli, BadInputIsAOneLineErrorAndNonZeroExit) {
  CliRun r = run("bvh /nonexistent/model.obj");
  EXPECT_EQ(r.status, 1);
  EXPECT_NE(r.out.find("/nonexistent/model.obj"), std::string::npos) << r.out;
  EXPECT_EQ(std::count(r.out.begin(), r.out.end(), '\n'), 1) << r.out;
  r = run("bvh builtin:cornell_box --builder quantum");
  EXPECT_NE(r.status, 0);
  EXPECT_NE(r.out.find("quantum"), std::string::npos) << r.out;
  r = run("bvh builtin:cornell_box --bins 99");
  EXPECT_NE(r.status, 0);
  r = run("trace builtin:cornell_box --rays /nonexistent.rays --hits /tmp/x.hits");
  EXPECT_EQ(r.status, 1);
  r = run("frobnicate");
  EXPECT_NE(r.status, 0);
  r = run("preview --res 0x10");
  EXPECT_EQ(r.status, 1);
  for (const char* cmd :
       {"render builtin:cornell_box --res 8x8 --quiet -o /tmp/kestrel_never.exr",
        "run builtin:cornell_box --res 16x16 --frames 1 --out /tmp/kestrel_never"}) {
    r = run(std::string(cmd) + " --indirect-rate 0.3");
    EXPECT_EQ(r.status, 1) << cmd;
    EXPECT_NE(r.out.find("indirect rate must be 1, 0.5 or 0.25"), std::string::npos) << r.out;
    EXPECT_EQ(std::count(r.out.begin(), r.out.end(), '\n'), 1) << r.out;
  }
  const std::string nan_obj =
      test::write_temp_file("all_nan.obj", "v nan 0 0\nv 0 nan 0\nv 0 0 nan\nf 1 2 3\n");
  r = run("bvh " + nan_obj);
  EXPECT_EQ(r.status, 1);
  EXPECT_NE(r.out.find("no valid triangle"), std::string::npos) << r.out;
}

TEST(Cli, BvhReportsMetricsAsJson) {
  const CliRun r = run("bvh builtin:cornell_box --builder sweep --threads 1 --repeat 2 --json");
  ASSERT_EQ(r.status, 0) << r.out;
  for (const char* key :
       {"\"sah_cost\"", "\"build_ms\"", "\"leaf_size_histogram\"", "\"bytes_per_prim\"",
        "\"valid\": true", "\"accel_build_ms\"", "\"accel_layout\""})
    EXPECT_NE(r.out.find(key), std::string::npos) << key;
}

TEST(Cli, RaysTraceHitsRoundTripMatchesTheLibrary) {
  const auto dir = test::test_temp_dir();
  std::filesystem::create_directories(dir);
  const std::string rays = (dir / "cb.rays").string(), hits = (dir / "cb.hits").string();
  for (const char* kind : {"primary", "diffuse"}) {
    CliRun r =
        run(std::string("rays builtin:cornell_box --kind ") + kind + " --res 64x48 -o " + rays);
    ASSERT_EQ(r.status, 0) << r.out;
    for (const char* builder : {"binned", "lbvh"}) {
      r = run("trace builtin:cornell_box --rays " + rays + " --hits " + hits + " --builder " +
              builder + " --threads 2");
      ASSERT_EQ(r.status, 0) << r.out;
      EXPECT_NE(r.out.find("Mrays/s"), std::string::npos);
      const auto in = read_rays(rays);
      const auto out = read_hits(hits);
      ASSERT_EQ(in.size(), out.size());
      const Accel accel = build_accel(load_scene("builtin:cornell_box"), BuildConfig{});
      for (size_t i = 0; i < in.size(); ++i) {
        const Hit h = intersect(accel, in[i]);
        ASSERT_EQ(out[i].hit(), h.hit()) << i;
        if (h.hit()) {
          ASSERT_EQ(out[i].t, h.t) << i;
        }
      }
    }
    r = run("trace builtin:cornell_box --any-hit --rays " + rays + " --hits " + hits);
    ASSERT_EQ(r.status, 0) << r.out;
    // Every layout / ISA / packet choice writes the same hits, bit for bit.
    const auto reference = [&] {
      run("trace builtin:cornell_box --layout bvh2 --rays " + rays + " --hits " + hits);
      return read_hits(hits);
    }();
    std::vector<std::string> variants = {
        "--layout bvh4 --isa sse2",    "--layout bvh8 --isa sse2 --packets on",
        "--layout bvh8 --packets off", "--quality auto --expected-rays 1e9",
        "--layout bvh8 --stream on",   "--layout bvh4 --stream on --packets off"};
    for (const char* isa : {"avx2", "avx512"})
      if (isa_supported(*isa_from_name(isa)))
        variants.push_back(std::string("--layout bvh8 --packets on --isa ") + isa);
    for (const std::string& v : variants) {
      r = run("trace builtin:cornell_box " + v + " --rays " + rays + " --hits " + hits);
      ASSERT_EQ(r.status, 0) << v << ": " << r.out;
      const auto got = read_hits(hits);
      ASSERT_EQ(got.size(), reference.size());
      for (size_t i = 0; i < got.size(); ++i) {
        ASSERT_EQ(got[i].prim_id, reference[i].prim_id) << v << " ray " << i;
        ASSERT_EQ(got[i].t, reference[i].t) << v << " ray " << i;
      }
    }
  }
  CliRun bad = run("trace builtin:cornell_box --isa avx1024 --rays " + rays + " --hits " + hits);
  EXPECT_EQ(bad.status, 1);
  EXPECT_NE(bad.out.find("unknown ISA 'avx1024'"), std::string::npos) << bad.out;
  bad = run("trace builtin:cornell_box --layout bvh16 --rays " + rays + " --hits " + hits);
  EXPECT_EQ(bad.status, 1);
  EXPECT_NE(bad.out.find("unknown layout 'bvh16'"), std::string::npos) << bad.out;
  bad = run("trace builtin:cornell_box --stream maybe --rays " + rays + " --hits " + hits);
  EXPECT_EQ(bad.status, 1);
  EXPECT_NE(bad.out.find("--stream 'maybe': expected auto, on or off"), std::string::npos)
      << bad.out;
}

TEST(Cli, PreviewWritesAPng) {
  const std::string png = (test::test_temp_dir() / "p.png").string();
  std::filesystem::create_directories(std::filesystem::path(png).parent_path());
  std::filesystem::remove(png);
  const CliRun r = run("preview -o " + png + " --res 64x64");
  ASSERT_EQ(r.status, 0) << r.out;
  std::ifstream f(png, std::ios::binary);
  char sig[8] = {};
  f.read(sig, 8);
  EXPECT_EQ(std::string(sig + 1, 3), "PNG");
}

TEST(Cli, RenderWritesEveryAovAndIsThreadIndependent) {
  const auto dir = test::test_temp_dir() / "cli_render";
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  const std::string d = dir.string();
  CliRun r = run("render builtin:cornell_box --res 48x32 --spp 2 --seed 7 --threads 1 --quiet -o " +
                 d + "/a.exr --pfm " + d + "/pfm --png " + d + "/a.png");
  ASSERT_EQ(r.status, 0) << r.out;
  EXPECT_NE(r.out.find("Mrays/s"), std::string::npos) << r.out;
  r = run("render builtin:cornell_box --res 48x32 --spp 2 --seed 7 --threads 2 --quiet -o " + d +
          "/b.exr");
  ASSERT_EQ(r.status, 0) << r.out;
  const auto a = read_exr(d + "/a.exr"), b = read_exr(d + "/b.exr");
  ASSERT_EQ(a.size(), 8u);
  for (size_t i = 0; i < a.size(); ++i)
    EXPECT_EQ(a[i].image.pixels, b[i].image.pixels) << a[i].name;
  for (const char* aov :
       {"color", "albedo", "normal", "depth", "roughness", "motion", "spp", "variance"})
    EXPECT_TRUE(std::filesystem::exists(d + "/pfm/" + aov + ".pfm")) << aov;
  EXPECT_TRUE(std::filesystem::exists(d + "/a.png"));
  // Bad input: one line naming the problem.
  r = run("render builtin:cornell_box --view nowhere -o " + d + "/c.exr");
  EXPECT_EQ(r.status, 1);
  EXPECT_NE(r.out.find("nowhere"), std::string::npos) << r.out;
  r = run("render builtin:cornell_box --camera 1,2,3 -o " + d + "/c.exr");
  EXPECT_EQ(r.status, 1);
  const std::string nan_obj =
      test::write_temp_file("render_nan.obj", "v nan 0 0\nv 0 1 0\nv 0 0 1\nf 1 2 3\n");
  r = run("render " + nan_obj + " -o " + d + "/c.exr");
  EXPECT_EQ(r.status, 1);
  EXPECT_NE(r.out.find("no valid triangle"), std::string::npos) << r.out;
  r = run("render builtin:cornell_box --env /no/sky.hdr -o " + d + "/c.exr");
  EXPECT_EQ(r.status, 1);
  EXPECT_NE(r.out.find("/no/sky.hdr"), std::string::npos) << r.out;
}

TEST(Cli, RenderSequenceWritesOneFileSetPerFrame) {
  const auto dir = test::test_temp_dir() / "cli_sequence";
  std::filesystem::remove_all(dir);
  const std::string path = test::write_temp_file("cli_path.json", R"({"keyframes": [
    {"time": 0, "eye": [0.278, 0.273, -0.8], "target": [0.278, 0.273, 0], "vfov": 39.3},
    {"time": 1, "eye": [0.35, 0.3, -0.7], "target": [0.25, 0.27, 0], "vfov": 39.3}]})");
  const CliRun r = run("render-sequence builtin:cornell_box --path " + path +
                       " --frames 3 --spp 1 --res 32x24 --quiet -o " + dir.string());
  ASSERT_EQ(r.status, 0) << r.out;
  for (int i = 0; i < 3; ++i)
    EXPECT_TRUE(std::filesystem::exists(dir / ("frame_000" + std::to_string(i) + ".exr"))) << i;
  // The camera moved: the second frame has non-zero motion vectors.
  const auto layers = read_exr((dir / "frame_0001.exr").string());
  float max_motion = 0;
  for (const auto& l : layers)
    if (l.name == "motion")
      for (float v : l.image.pixels) max_motion = std::max(max_motion, std::fabs(v));
  EXPECT_GT(max_motion, 0.1f);
  const auto scene = test::shared_scene("gltf_box_animated/BoxAnimated.gltf");
  if (scene) {
    const CliRun g =
        run("render-sequence " + *scene + " --path " + std::string(KESTREL_DATA_DIR) +
            "/paths/box_animated_orbit.json --frames 2 --spp 1 --res 32x24 --quiet -o " +
            (dir / "gltf").string());
    EXPECT_EQ(g.status, 0) << g.out;
  }
}

TEST(Cli, RenderSequenceOrbitsAndDenoises) {
  const auto dir = test::test_temp_dir() / "cli_orbit";
  std::filesystem::remove_all(dir);
  const CliRun r =
      run("render-sequence builtin:cornell_box --path orbit:20 --frames 2 --spp 1 --res 32x24 "
          "--quiet --denoise svgf -o " +
          dir.string() + " --pfm " + (dir / "pfm").string());
  ASSERT_EQ(r.status, 0) << r.out;
  // The denoised colour replaces the colour layer; the noisy one is kept beside it.
  const auto layers = read_exr((dir / "frame_0001.exr").string());
  bool noisy = false;
  for (const auto& l : layers) noisy = noisy || l.name == "noisy";
  EXPECT_TRUE(noisy);
  EXPECT_TRUE(std::filesystem::exists(dir / "pfm" / "frame_0001" / "noisy.pfm"));
  EXPECT_NE(run("render-sequence builtin:cornell_box --path orbit:x --frames 2 -o " + dir.string())
                .status,
            0);
  EXPECT_NE(
      run("render builtin:cornell_box --res 8x8 --denoise magic -o " + (dir / "x.exr").string())
          .status,
      0);
}

TEST(Cli, DenoiseReadsPfmsAndExrSequences) {
  const std::string fix = std::string(KESTREL_SOURCE_DIR) + "/tests/data/denoise/frame_%d/";
  const auto dir = test::test_temp_dir() / "cli_denoise";
  std::filesystem::remove_all(dir);
  for (const char* method : {"neural", "svgf", "atrous"}) {
    const std::string out = (dir / (std::string(method) + "_%d.pfm")).string();
    const CliRun r =
        run("denoise --sequence --frames 2 --hdr " + fix + "color.pfm --alb " + fix +
            "albedo.pfm --nrm " + fix + "normal.pfm --depth " + fix + "depth.pfm --rough " + fix +
            "roughness.pfm --motion " + fix + "motion.pfm --method " + method + " -o " + out);
    ASSERT_EQ(r.status, 0) << method << ": " << r.out;
    const FloatImage img = read_pfm((dir / (std::string(method) + "_1.pfm")).string());
    EXPECT_EQ(img.width, 44);
    EXPECT_EQ(img.height, 30);
    for (float v : img.pixels) ASSERT_TRUE(std::isfinite(v)) << method;
  }
  // kestrel's own multi-layer EXRs in, EXR out.
  const auto frames = dir / "frames";
  ASSERT_EQ(run("render-sequence builtin:cornell_box --path orbit:10 --frames 2 --spp 1 --res "
                "24x16 --quiet -o " +
                frames.string())
                .status,
            0);
  const CliRun e = run("denoise --sequence --frames 2 -i " + (frames / "frame_%04d.exr").string() +
                       " -o " + (dir / "exr_%02d.exr").string());
  ASSERT_EQ(e.status, 0) << e.out;
  EXPECT_TRUE(std::filesystem::exists(dir / "exr_01.exr"));
  // Errors: a size mismatch names the input; a pattern without %d; no colour.
  const std::string small = (dir / "small.pfm").string();
  write_pfm(small, FloatImage(8, 8, 3));
  CliRun bad = run("denoise --hdr " + std::string(KESTREL_SOURCE_DIR) +
                   "/tests/data/denoise/frame_0/color.pfm --alb " + small + " -o " +
                   (dir / "bad.pfm").string());
  EXPECT_EQ(bad.status, 1);
  EXPECT_NE(bad.out.find("albedo is 8x8"), std::string::npos) << bad.out;
  bad = run("denoise --sequence --frames 2 --hdr " + small + " -o " + (dir / "x.pfm").string());
  EXPECT_EQ(bad.status, 1);
  EXPECT_NE(bad.out.find("%d"), std::string::npos) << bad.out;
  EXPECT_EQ(run("denoise -o " + (dir / "x.pfm").string()).status, 1);
}

// A command that runs a oneDNN network (rae here) executes itself again with OMP_WAIT_POLICY
// set to passive unless the user set it; libgomp itself reports what it read
// (OMP_DISPLAY_ENV=verbose, once per process start: GOMP_SPINCOUNT 0 under passive, 300000
// by default, 3e10 under active). Other commands start once.
TEST(Cli, OnednnCommandsMakeOpenMpThreadsSleep) {
  const std::string frame = (test::test_temp_dir() / "cli_openmp" / "frame.exr").string();
  ASSERT_EQ(run("render builtin:cornell_box --spp 1 --res 24x16 --quiet -o " + frame).status, 0);
  auto display = [&](const std::string& env, const std::string& method) {
    return run(
        "denoise -i " + frame + " -o " + frame + "." + method + ".exr --quiet --method " + method,
        "env -u OMP_WAIT_POLICY OMP_DISPLAY_ENV=verbose " + env);
  };
  CliRun r = display("", "rae");
  ASSERT_EQ(r.status, 0) << r.out;
  EXPECT_NE(r.out.find("GOMP_SPINCOUNT = '0'"), std::string::npos) << r.out;
  r = display("OMP_WAIT_POLICY=active", "rae");
  ASSERT_EQ(r.status, 0) << r.out;
  EXPECT_EQ(r.out.find("GOMP_SPINCOUNT = '0'"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("GOMP_SPINCOUNT = '30000000000'"), std::string::npos) << r.out;
  r = display("", "neural");
  ASSERT_EQ(r.status, 0) << r.out;
  EXPECT_EQ(r.out.find("GOMP_SPINCOUNT = '0'"), std::string::npos) << r.out;
}

TEST(Cli, UpscaleAndRenderSequenceUpscale) {
  const auto dir = test::test_temp_dir() / "cli_upscale";
  std::filesystem::remove_all(dir);
  // Low-resolution frames (fixed jitter), then every method at both factors.
  const auto frames = dir / "low";
  ASSERT_EQ(run("render-sequence builtin:cornell_box --path orbit:10 --frames 3 --spp 4 "
                "--fixed-jitter --res 24x16 --quiet -o " +
                frames.string())
                .status,
            0);
  for (const char* method : {"neural", "taau", "bicubic", "bilinear"})
    for (int f : {2, 4}) {
      const std::string out = (dir / fmt::format("{}_x{}_%04d.exr", method, f)).string();
      const CliRun r =
          run(fmt::format("upscale --sequence {} --factor {} --method {} -o {} --quiet",
                          (frames / "frame_%04d.exr").string(), f, method, out));
      ASSERT_EQ(r.status, 0) << method << ": " << r.out;
      EXPECT_NE(r.out.find("3 frames"), std::string::npos) << r.out;  // every consecutive file
      const auto layers = read_exr((dir / fmt::format("{}_x{}_0002.exr", method, f)).string());
      ASSERT_FALSE(layers.empty());
      EXPECT_EQ(layers[0].image.width, 24 * f);
      EXPECT_EQ(layers[0].image.height, 16 * f);
      for (float v : layers[0].image.pixels) ASSERT_TRUE(std::isfinite(v) && v >= 0) << method;
    }
  // render-sequence --upscale: full-resolution frames, low-resolution ones under low/.
  const auto seq = dir / "seq";
  const CliRun r =
      run("render-sequence builtin:cornell_box --path orbit:10 --frames 2 --res 48x32 --upscale "
          "taau --factor 4 --quiet -o " +
          seq.string());
  ASSERT_EQ(r.status, 0) << r.out;
  EXPECT_EQ(read_exr((seq / "frame_0001.exr").string())[0].image.width, 48);
  EXPECT_EQ(read_exr((seq / "low" / "frame_0001.exr").string())[0].image.width, 12);
  // Errors name the problem.
  CliRun bad = run("upscale --sequence " + (frames / "frame_%04d.exr").string() +
                   " --factor 3 -o " + (dir / "x_%d.exr").string());
  EXPECT_EQ(bad.status, 1);
  EXPECT_NE(bad.out.find("factor"), std::string::npos) << bad.out;
  bad = run("upscale -i /nonexistent/frame.exr -o " + (dir / "x.exr").string());
  EXPECT_EQ(bad.status, 1);
  EXPECT_NE(bad.out.find("/nonexistent/frame.exr"), std::string::npos) << bad.out;
  bad =
      run("render-sequence builtin:cornell_box --path orbit:10 --frames 1 --res 30x30 --upscale "
          "neural --factor 4 -o " +
          seq.string());
  EXPECT_EQ(bad.status, 1);
  EXPECT_NE(bad.out.find("divisible"), std::string::npos) << bad.out;
}

TEST(Cli, RunWritesFramesAndAStageTable) {
  const auto dir = test::test_temp_dir() / "cli_run";
  std::filesystem::remove_all(dir);
  const CliRun r =
      run("run builtin:cornell_box --path orbit:20 --frames 3 --res 64x48 --internal 16x12 "
          "--max-depth 2 --quiet --exr -o " +
          dir.string());
  ASSERT_EQ(r.status, 0) << r.out;
  for (const char* f :
       {"frame_0000.png", "frame_0002.png", "frame_0002.exr", "timings.md", "timings.csv"})
    EXPECT_TRUE(std::filesystem::exists(dir / f)) << f;
  std::ifstream md(dir / "timings.md");
  const std::string table((std::istreambuf_iterator<char>(md)), std::istreambuf_iterator<char>());
  for (const char* stage : {"| render |", "| denoise |", "| upscale |", "| tone map |", "| frame |",
                            "frames per second"})
    EXPECT_NE(table.find(stage), std::string::npos) << stage << "\n" << table;
  EXPECT_NE(table.find("16x12 internal (x4)"), std::string::npos) << table;
  // Where the render's time goes: one camera ray per internal pixel and sample, the other
  // kinds counted, the trace share a fraction.
  EXPECT_NE(table.find("Rays per frame (median): 192 camera"), std::string::npos) << table;
  {
    std::ifstream csv(dir / "timings.csv");
    std::string header, row;
    std::getline(csv, header), std::getline(csv, row);
    EXPECT_NE(header.find(",camera_rays,bounce_rays,shadow_rays,trace_share"), std::string::npos)
        << header;
    std::vector<std::string> cells;
    for (size_t at = 0, next; at <= row.size(); at = next + 1) {
      next = row.find(',', at);
      if (next == std::string::npos) next = row.size();
      cells.push_back(row.substr(at, next - at));
    }
    ASSERT_EQ(cells.size(), 13u) << row;
    EXPECT_EQ(cells[9], "192") << row;
    EXPECT_GT(std::stoull(cells[10]) + std::stoull(cells[11]), 0u) << row;
    const double share = std::stod(cells[12]);
    EXPECT_GT(share, 0.0) << row;
    EXPECT_LT(share, 1.0) << row;
  }
  EXPECT_EQ(read_exr((dir / "frame_0002.exr").string())[0].image.width, 64);
  // Same path, same settings: the same frames (deterministic pipeline).
  const auto again = dir / "again";
  ASSERT_EQ(run("run builtin:cornell_box --path orbit:20 --frames 3 --res 64x48 --internal 16x12 "
                "--max-depth 2 --quiet --threads 1 -o " +
                again.string())
                .status,
            0);
  std::ifstream a(dir / "frame_0002.png", std::ios::binary),
      b(again / "frame_0002.png", std::ios::binary);
  const std::string pa((std::istreambuf_iterator<char>(a)), std::istreambuf_iterator<char>());
  const std::string pb((std::istreambuf_iterator<char>(b)), std::istreambuf_iterator<char>());
  EXPECT_TRUE(!pa.empty() && pa == pb) << "1 thread and all threads differ";
  CliRun bad = run("run builtin:cornell_box --res 64x48 --internal 30x12 -o " + again.string());
  EXPECT_EQ(bad.status, 1);
  EXPECT_NE(bad.out.find("--internal 30x12"), std::string::npos) << bad.out;
  bad = run("run builtin:cornell_box --denoise fancy -o " + again.string());
  EXPECT_EQ(bad.status, 1);
  EXPECT_NE(bad.out.find("fancy"), std::string::npos) << bad.out;
}

// `run` (and `view`, the same options) take a lights file as `render` does: its point light
// brightens the loop's frame, and a bad light is an error naming the file and the light.
TEST(Cli, RunTakesALightsFile) {
  const auto dir = test::test_temp_dir() / "cli_run_lights";
  std::filesystem::remove_all(dir);
  const std::string lights = test::write_temp_file(
      "run.lights.json",
      R"({"lights": [{"name": "bulb", "type": "point", "position": [0.28, 0.3, 0.28], "intensity": 0.5}]})");
  const std::string common =
      "run builtin:cornell_box --path orbit:0 --frames 1 --res 32x24 --factor 1 --denoise none "
      "--max-depth 2 --quiet --no-png --exr ";
  ASSERT_EQ(run(common + "-o " + (dir / "off").string()).status, 0);
  const CliRun on = run(common + "--lights " + lights + " -o " + (dir / "on").string());
  ASSERT_EQ(on.status, 0) << on.out;
  const auto mean = [&](const char* sub) {
    const FloatImage img = read_exr((dir / sub / "frame_0000.exr").string())[0].image;
    double sum = 0;
    for (int y = 0; y < img.height; ++y)
      for (int x = 0; x < img.width; ++x) sum += img.at(x, y)[0] + img.at(x, y)[1];
    return sum / double(img.width * img.height);
  };
  EXPECT_GT(mean("on"), 1.5 * mean("off"));
  const std::string bad = test::write_temp_file(
      "bad_run.lights.json", R"({"lights": [{"name": "dim", "type": "point", "intensity": -1}]})");
  const CliRun r = run(common + "--lights " + bad + " -o " + (dir / "bad").string());
  EXPECT_EQ(r.status, 1);
  EXPECT_NE(r.out.find("bad_run.lights.json"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("dim"), std::string::npos) << r.out;
}

}  // namespace
}  // namespace kestrel
