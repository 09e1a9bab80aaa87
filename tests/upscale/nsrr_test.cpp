// The nsrr upsampler: against PyTorch on a committed fixture (fp32 closely, bf16 within its
// precision), its weights file's checks, and its input checks.
#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <nlohmann/json.hpp>

#include "kestrel/error.h"
#include "kestrel/io.h"
#include "kestrel/upscale.h"

namespace kestrel {
namespace {

const std::string kFixture = std::string(KESTREL_SOURCE_DIR) + "/tests/data/upscale_nsrr";
// The weights the fixture was made with (train_nsrr.py writes both).
const std::string kWeights = kFixture + "/weights.kdw";

UpscalerOptions nsrr(int factor, bool bf16 = false, const std::string& weights = kWeights) {
  UpscalerOptions o;
  o.method = UpscaleMethod::nsrr, o.factor = factor, o.bf16 = bf16, o.weights = weights;
  return o;
}

struct FixtureFrame {
  FloatImage color, depth, motion, expected;
  float jx = 0.5f, jy = 0.5f;
};

std::vector<FixtureFrame> load_fixture(int f) {
  std::ifstream meta_file(kFixture + "/fixture.json");
  EXPECT_TRUE(meta_file) << kFixture;
  const nlohmann::json meta = nlohmann::json::parse(meta_file);
  std::vector<FixtureFrame> frames;
  for (int t = 0; t < int(meta["frames"]); ++t) {
    const std::string p = kFixture + "/x" + std::to_string(f) + "_";
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
void compare(bool bf16, double worst_allowed, double psnr_required) {
  for (int f : {2, 4}) {
    const std::vector<FixtureFrame> frames = load_fixture(f);
    ASSERT_FALSE(frames.empty());
    Upscaler up(nsrr(f, bf16));
    for (size_t t = 0; t < frames.size(); ++t) {
      const FixtureFrame& fr = frames[t];
      const FloatImage out = up.upscale({&fr.color, &fr.depth, &fr.motion, fr.jx, fr.jy});
      ASSERT_EQ(out.width, fr.expected.width);
      ASSERT_EQ(out.height, fr.expected.height);
      double worst = 0, se = 0;
      for (size_t i = 0; i < out.pixels.size(); ++i) {
        const double d = std::abs(double(out.pixels[i]) - fr.expected.pixels[i]);
        worst = std::max(worst, d / (std::abs(fr.expected.pixels[i]) + 1e-2));
        se += d * d;
      }
      const double psnr = 10 * std::log10(double(out.pixels.size()) / std::max(se, 1e-30));
      EXPECT_LT(worst, worst_allowed) << "factor " << f << " frame " << t;
      EXPECT_GT(psnr, psnr_required) << "factor " << f << " frame " << t;
    }
  }
}

TEST(Nsrr, MatchesPyTorchOnTheFixtureInFp32) {
  compare(false, 2e-3, 60.0);
}

TEST(Nsrr, Bf16StaysCloseToPyTorch) {
  Upscaler up(nsrr(2, true));
  if (!up.uses_bf16()) GTEST_SKIP() << "this CPU has no bf16 convolutions";
  compare(true, 1.0, 30.0);
}

TEST(Nsrr, CorruptOrForeignWeightsAreErrorsNamingTheFile) {
  std::ifstream in(kWeights, std::ios::binary);
  std::vector<char> bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  ASSERT_GT(bytes.size(), 1000u);
  const std::string dir = testing::TempDir();
  auto expect_error = [&](const std::string& name, const std::vector<char>& b) {
    const std::string path = dir + name;
    std::ofstream(path, std::ios::binary).write(b.data(), std::streamsize(b.size()));
    try {
      Upscaler up(nsrr(2, false, path));
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
  EXPECT_THROW(Upscaler(nsrr(2, false, dir + "does_not_exist.kdw")), Error);
}

TEST(Nsrr, BadInputIsAnError) {
  Upscaler up(nsrr(2));
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

}  // namespace
}  // namespace kestrel
