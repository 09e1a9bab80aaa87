// The nsrr family (nsrr and its real-time member nsrr-rt): against PyTorch on committed
// fixtures (fp32 closely, bf16 within its precision), their weights files' checks, and their
// input checks.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <random>

#include "kestrel/error.h"
#include "kestrel/io.h"
#include "kestrel/isa.h"
#include "kestrel/upscale.h"
#include "support/oracles.h"
#include "upscale/nsrr_warp.h"

namespace kestrel {
namespace {

// The fixture of a member (train_nsrr.py writes it with the weights it was made with).
std::string fixture_of(UpscaleMethod m) {
  return std::string(KESTREL_SOURCE_DIR) +
         (m == UpscaleMethod::nsrr ? "/tests/data/upscale_nsrr" : "/tests/data/upscale_nsrr_rt");
}
std::string weights_of(UpscaleMethod m) {
  return fixture_of(m) + "/weights.kdw";
}

UpscalerOptions nsrr(UpscaleMethod m, int factor, bool bf16 = false, std::string weights = "") {
  UpscalerOptions o;
  o.method = m, o.factor = factor, o.bf16 = bf16;
  o.weights = weights.empty() ? weights_of(m) : weights;
  return o;
}

class Nsrr : public testing::TestWithParam<UpscaleMethod> {};

struct FixtureFrame {
  FloatImage color, depth, motion, expected;
  float jx = 0.5f, jy = 0.5f;
};

std::vector<FixtureFrame> load_fixture(UpscaleMethod m, int f) {
  const std::string fixture = fixture_of(m);
  std::ifstream meta_file(fixture + "/fixture.json");
  EXPECT_TRUE(meta_file) << fixture;
  const nlohmann::json meta = nlohmann::json::parse(meta_file);
  std::vector<FixtureFrame> frames;
  for (int t = 0; t < int(meta["frames"]); ++t) {
    const std::string p = fixture + "/x" + std::to_string(f) + "_";
    const std::string s = std::to_string(t) + ".pfm";
    FixtureFrame fr;
    fr.color = read_pfm(p + "color_" + s);
    const FloatImage depth3 = read_pfm(p + "depth_" + s);
    fr.motion = read_pfm(p + "motion_" + s);
    fr.expected = read_pfm(p + "out_" + s);
    fr.depth = FloatImage(depth3.width, depth3.height, 1);
    for (size_t i = 0; i < fr.depth.pixels.size(); ++i)
      fr.depth.pixels[i] = depth3.pixels[i * size_t(depth3.channels)];
    fr.jx = meta["jitter"][size_t(t)][0], fr.jy = meta["jitter"][size_t(t)][1];
    frames.push_back(std::move(fr));
  }
  return frames;
}

// Per frame: the worst error relative to |expected| + 0.01, and the PSNR (peak 1) of the
// output against PyTorch's.
void compare(UpscaleMethod m, bool bf16, double worst_allowed, double psnr_required) {
  for (int f : {2, 4}) {
    const std::vector<FixtureFrame> frames = load_fixture(m, f);
    ASSERT_FALSE(frames.empty());
    Upscaler up(nsrr(m, f, bf16));
    for (size_t t = 0; t < frames.size(); ++t) {
      const FixtureFrame& fr = frames[t];
      const FloatImage out = up.upscale({&fr.color, &fr.depth, &fr.motion, fr.jx, fr.jy});
      ASSERT_EQ(out.width, fr.expected.width);
      ASSERT_EQ(out.height, fr.expected.height);
      const test::ImageMatch m = test::match_images(out, fr.expected);
      EXPECT_LT(m.worst, worst_allowed) << "factor " << f << " frame " << t;
      EXPECT_GT(m.psnr, psnr_required) << "factor " << f << " frame " << t;
    }
  }
}

TEST_P(Nsrr, MatchesPyTorchOnTheFixtureInFp32) {
  compare(GetParam(), false, 2e-3, 60.0);
}

TEST_P(Nsrr, Bf16StaysCloseToPyTorch) {
  Upscaler up(nsrr(GetParam(), 2, true));
  if (!up.uses_bf16()) GTEST_SKIP() << "this CPU has no bf16 convolutions";
  compare(GetParam(), true, 1.0, 30.0);
}

TEST_P(Nsrr, CorruptOrForeignWeightsAreErrorsNamingTheFile) {
  const UpscaleMethod m = GetParam();
  std::ifstream in(weights_of(m), std::ios::binary);
  std::vector<char> bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  ASSERT_GT(bytes.size(), 1000u);
  const std::string dir = testing::TempDir();
  auto expect_error = [&](const std::string& name, const std::vector<char>& b) {
    const std::string path = dir + upscale_method_name(m) + name;
    std::ofstream(path, std::ios::binary).write(b.data(), std::streamsize(b.size()));
    try {
      Upscaler up(nsrr(m, 2, false, path));
      ADD_FAILURE() << name << " was accepted";
    } catch (const Error& e) {
      EXPECT_NE(std::string(e.what()).find(path), std::string::npos) << e.what();
    }
  };
  expect_error("nsrr_truncated.kdw", std::vector<char>(bytes.begin(), bytes.begin() + 500));
  std::vector<char> flipped = bytes;
  flipped[bytes.size() / 2] ^= 0x40;
  expect_error("nsrr_flipped.kdw", flipped);
  // The learned TAAU's weights are not nsrr's.
  std::ifstream taau(std::string(KESTREL_SOURCE_DIR) + "/weights/upscaler.kdw", std::ios::binary);
  expect_error("nsrr_foreign.kdw", std::vector<char>((std::istreambuf_iterator<char>(taau)),
                                                     std::istreambuf_iterator<char>()));
  // Nor are the other member's (the same magic, another architecture).
  std::ifstream other(
      weights_of(m == UpscaleMethod::nsrr ? UpscaleMethod::nsrr_rt : UpscaleMethod::nsrr),
      std::ios::binary);
  expect_error("nsrr_other.kdw", std::vector<char>((std::istreambuf_iterator<char>(other)),
                                                   std::istreambuf_iterator<char>()));
  EXPECT_THROW(Upscaler(nsrr(m, 2, false, dir + "does_not_exist.kdw")), Error);
}

// The history runs the learned TAAU's default weights ($KESTREL_WEIGHTS_DIR/upscaler.kdw): a
// corrupt one there is an error naming it, even though the member's own weights are fine.
TEST_P(Nsrr, CorruptHistoryWeightsAreAnErrorNamingTheFile) {
  const std::string dir = testing::TempDir() + "nsrr_history_" + upscale_method_name(GetParam());
  std::filesystem::create_directories(dir);
  const std::string path = dir + "/upscaler.kdw";
  std::ifstream in(std::string(KESTREL_SOURCE_DIR) + "/weights/upscaler.kdw", std::ios::binary);
  std::vector<char> bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  ASSERT_GT(bytes.size(), 1000u);
  std::ofstream(path, std::ios::binary).write(bytes.data(), std::streamsize(bytes.size() / 2));
  const char* before = std::getenv("KESTREL_WEIGHTS_DIR");
  const std::string saved = before ? before : "";
  setenv("KESTREL_WEIGHTS_DIR", dir.c_str(), 1);
  try {
    Upscaler up(nsrr(GetParam(), 2));
    ADD_FAILURE() << "a truncated history weights file was accepted";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find(path), std::string::npos) << e.what();
  }
  if (before)
    setenv("KESTREL_WEIGHTS_DIR", saved.c_str(), 1);
  else
    unsetenv("KESTREL_WEIGHTS_DIR");
}

TEST_P(Nsrr, BadInputIsAnError) {
  Upscaler up(nsrr(GetParam(), 2));
  FloatImage color(16, 12, 3), depth(16, 12, 1), motion(16, 12, 2), small(8, 12, 1);
  EXPECT_THROW(up.upscale({&color, nullptr, &motion}), Error);  // nsrr needs depth
  EXPECT_THROW(up.upscale({&color, &depth, nullptr}), Error);   // and motion
  EXPECT_THROW(up.upscale({&color, &small, &motion}), Error);
  EXPECT_THROW(up.upscale({&color, &depth, &motion, NAN, 0.5f}), Error);
  // NaN and Inf samples read as 0: a finite output.
  color.pixels[5] = NAN, depth.pixels[3] = INFINITY, motion.pixels[7] = -INFINITY;
  const FloatImage out = up.upscale({&color, &depth, &motion});
  for (float v : out.pixels) ASSERT_TRUE(std::isfinite(v));
  // A size change starts a new sequence.
  FloatImage c2(20, 8, 3), d2(20, 8, 1), m2(20, 8, 2);
  EXPECT_EQ(up.upscale({&c2, &d2, &m2}).width, 40);
}

// The reconstruction is a softmax blend of the bilinear base, the learned TAAU's output (the
// history) and the window's samples, so whatever the trained weights predict, every output
// pixel's y = c / (1 + L(c)) lies within the range of the y of the samples of the frames in its
// window and of the history at that pixel (the learned TAAU run alongside on the same frames;
// grey samples here, so no channel reaches the y clamp): no member can brighten or darken beyond
// what was sampled or accumulated.
TEST_P(Nsrr, OutputStaysWithinItsCandidates) {
  for (int f : {2, 4}) {
    Upscaler up(nsrr(GetParam(), f));
    UpscalerOptions taau_options;
    taau_options.method = UpscaleMethod::neural, taau_options.factor = f;
    Upscaler taau(taau_options);
    std::mt19937 rng(7 + f);
    std::uniform_real_distribution<float> u(0.0f, 1.0f);
    const int w = 24, h = 16, window = GetParam() == UpscaleMethod::nsrr ? 4 : 3;
    std::vector<std::pair<float, float>> range;  // per frame: min and max y of its samples
    for (int t = 0; t < 8; ++t) {
      FloatImage color(w, h, 3), depth(w, h, 1), motion(w, h, 2);
      // A bright frame every third one: a window holding it may reach its y, one without it
      // may not (unless the history holds it).
      const float scale = t % 3 == 1 ? 40.0f : 2.0f;
      float lo = INFINITY, hi = 0.0f;
      for (size_t p = 0; p < size_t(w) * size_t(h); ++p) {
        const float v = u(rng) < 0.1f ? 0.0f : scale * u(rng);
        for (size_t c = 0; c < 3; ++c) color.pixels[3 * p + c] = v;
        lo = std::min(lo, v / (1 + v)), hi = std::max(hi, v / (1 + v));
        depth.pixels[p] = u(rng) < 0.05f ? 0.0f : 1.0f + 4.0f * u(rng);
        motion.pixels[2 * p] = 3.0f * (u(rng) - 0.5f), motion.pixels[2 * p + 1] = u(rng) - 0.5f;
      }
      range.emplace_back(lo, hi);
      const auto [jx, jy] = std::pair{u(rng), u(rng)};
      const FloatImage out = up.upscale({&color, &depth, &motion, jx, jy});
      const FloatImage hist = taau.upscale({&color, &depth, &motion, jx, jy});
      float wlo = INFINITY, whi = 0.0f;
      for (int k = std::max(0, t - window + 1); k <= t; ++k)
        wlo = std::min(wlo, range[size_t(k)].first), whi = std::max(whi, range[size_t(k)].second);
      auto y_of = [](const float* c, size_t ch) {
        return c[ch] / (1 + 0.2126f * c[0] + 0.7152f * c[1] + 0.0722f * c[2]);
      };
      for (size_t q = 0; q < out.pixels.size(); q += 3)
        for (size_t ch = 0; ch < 3; ++ch) {
          const float y = y_of(&out.pixels[q], ch), hy = y_of(&hist.pixels[q], ch);
          ASSERT_GE(y, std::min(wlo, hy) - 1e-4f) << "factor " << f << " frame " << t;
          ASSERT_LE(y, std::max(whi, hy) + 1e-4f) << "factor " << f << " frame " << t;
        }
    }
  }
}

// The warp's AVX-512 row against the scalar row it must reproduce bit for bit: rows whose
// length is no multiple of 16, motion that sends positions off every edge, both factors;
// motion noisy from pixel to pixel (the lanes' taps far apart: gathers) and smooth (a few
// neighbouring entries: loads and permutes); sample tables with gaps.
TEST(NsrrWarp, Avx512RowIsTheScalarRow) {
  if (!isa_supported(Isa::avx512)) GTEST_SKIP() << "this CPU has no AVX-512";
  std::mt19937 rng(5);
  std::uniform_real_distribution<float> u(-1.0f, 1.0f);
  for (bool smooth : {false, true})
    for (int f : {2, 4})
      for (int w : {1, 7, 13, 40, 70}) {
        const int h = 9, W = f * w, H = f * h;
        std::vector<float> motion(2 * size_t(w) * size_t(h));
        const float drift = 6.0f * u(rng);
        for (size_t p = 0; p < motion.size(); ++p)
          motion[p] = smooth ? drift + 0.01f * float(p % size_t(w)) + 0.2f * u(rng) : 3.0f * u(rng);
        std::vector<int32_t> col_at(static_cast<size_t>(W)), row_at(static_cast<size_t>(H));
        for (size_t X = 0; X < col_at.size(); ++X)
          col_at[X] = X % size_t(f) != 0 || X % 7 == 3 ? -1 : int32_t(X) / f;
        for (size_t Y = 0; Y < row_at.size(); ++Y)
          row_at[Y] = Y % size_t(f) != 1 ? -1 : int32_t(Y) / f;
        const upscale::nsrr::WarpRow a{motion.data(),
                                       motion.data() + size_t(w) * size_t(h),
                                       col_at.data(),
                                       row_at.data(),
                                       w,
                                       h,
                                       W,
                                       H,
                                       float(f),
                                       1.0f / float(f)};
        for (int Y = 0; Y < H; ++Y) {
          std::vector<float> p(2 * size_t(W));
          for (int X = 0; X < W; ++X)
            p[2 * size_t(X)] = float(X) + 0.5f + (smooth ? 0.0f : u(rng)),
                  p[2 * size_t(X) + 1] = float(Y) + 0.5f;
          std::vector<float> q = p;
          std::vector<int32_t> o1(static_cast<size_t>(W)), o2(static_cast<size_t>(W), 99);
          for (int step = 0; step < 3; ++step) {  // accumulated: positions fed back
            upscale::nsrr::warp_row_scalar(a, p.data(), o1.data());
            upscale::nsrr::warp_row_avx512(a, q.data(), o2.data());
            ASSERT_EQ(p, q) << "f " << f << " w " << w << " row " << Y << " step " << step;
            ASSERT_EQ(o1, o2) << "f " << f << " w " << w << " row " << Y << " step " << step;
          }
        }
      }
}

// nsrr-rt's grid fill, AVX-512 against scalar: partial cells at the right and bottom edges,
// frames missing from the window, the history's channels, bf16 and float grids.
TEST(NsrrWarp, Avx512GridIsTheScalarGrid) {
  if (!isa_supported(Isa::avx512)) GTEST_SKIP() << "this CPU has no AVX-512";
  using upscale::nsrr::GridFill;
  std::mt19937 rng(9);
  const int W = 22, H = 13, Gw = 6, Gh = 4;
  const size_t n = 40;
  std::vector<float> packed(GridFill::kFrames * GridFill::kX * n);
  for (size_t i = 0; i < packed.size(); ++i) {
    // Rounding to bf16 probed where it is decided: low halves just below, at and above a tie.
    float v = std::uniform_real_distribution<float>(0.0f, 1.0f)(rng);
    uint32_t u;
    std::memcpy(&u, &v, 4);
    const uint32_t low[4] = {0x7FFFu, 0x8000u, 0x8001u, 0x18000u};
    u = (u & 0xFFFE0000u) | low[i % 4];
    std::memcpy(&packed[i], &u, 4);
  }
  std::vector<float> hist(3 * size_t(W * H));  // the history's y, bf16 ties probed as above
  for (size_t i = 0; i < hist.size(); ++i) hist[i] = packed[i % packed.size()];
  std::vector<int32_t> at(GridFill::kFrames * size_t(W * H));
  for (int32_t& i : at) i = std::uniform_int_distribution<int32_t>(-3, int32_t(n) - 1)(rng);
  for (bool bf16 : {false, true})
    for (int frames : {1, 3}) {
      const size_t bytes = size_t(Gw * Gh * GridFill::kChannels) * (bf16 ? 2 : 4);
      std::vector<unsigned char> g1(bytes, 0xAB), g2(bytes, 0xCD);
      GridFill a{};
      for (int k = 0; k < GridFill::kFrames; ++k) a.at[k] = at.data() + size_t(k * W * H);
      a.frames = frames, a.packed = packed.data(), a.n = n, a.hist = hist.data(), a.W = W, a.H = H,
      a.Gw = Gw;
      a.last = 0.5f, a.bf16 = bf16;
      a.grid = g1.data();
      upscale::nsrr::grid_rows_scalar(a, 0, Gh);
      a.grid = g2.data();
      upscale::nsrr::grid_rows_avx512(a, 0, Gh);
      EXPECT_EQ(g1, g2) << "bf16 " << bf16 << " frames " << frames;
    }
}

TEST(NsrrWarp, EveryIsaGivesTheFixtureResult) {
  // The fp32 fixture comparison on every ISA this CPU has: the scalar warp and grid (what a CPU
  // without AVX-512 runs) and each ISA's zero-upsampling and blend (reconstruct_*.cpp).
  const Isa before = default_isa();
  for (Isa isa : {Isa::sse2, Isa::avx2, Isa::avx512}) {
    if (!isa_supported(isa)) continue;
    set_default_isa(isa);
    for (UpscaleMethod m : {UpscaleMethod::nsrr_rt, UpscaleMethod::nsrr}) {
      SCOPED_TRACE(isa_name(isa));
      compare(m, false, 2e-3, 60.0);
    }
  }
  set_default_isa(before);
}

INSTANTIATE_TEST_SUITE_P(Members, Nsrr,
                         testing::Values(UpscaleMethod::nsrr, UpscaleMethod::nsrr_rt),
                         [](const testing::TestParamInfo<UpscaleMethod>& i) {
                           return i.param == UpscaleMethod::nsrr ? "nsrr" : "nsrr_rt";
                         });

}  // namespace
}  // namespace kestrel
