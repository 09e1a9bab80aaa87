// Test support: scene generators with known properties and paths to the shared scenes.
#pragma once
#include <cstdint>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include "kestrel/kestrel.h"

namespace kestrel::test {

/// splitmix64, fixed seeds everywhere.
struct Rng {
  uint64_t state;
  uint64_t next();
  float uniform();  ///< [0, 1)
  float uniform(float lo, float hi);
  Vec3 in_box(Vec3 lo, Vec3 hi);
  Vec3 on_sphere();  ///< unit vector, uniform
};

/// n random triangles in the unit cube with edge lengths up to `size` (a soup: overlaps,
/// slivers and all).
Scene random_soup(size_t n, float size, uint64_t seed);

/// A random soup of `n` small triangles in the unit cube plus `far` finite triangles near the
/// float limit: every other one spans ±3e38 (its box's area and its edges' differences
/// overflow float), the rest sit near +3.3e38 (their doubled centroids overflow).
Scene soup_with_far_triangles(size_t n, size_t far, uint64_t seed);

/// A closed, watertight triangulated sphere (subdivided icosahedron), vertices shared.
Scene closed_sphere(int subdivisions, Vec3 center, float radius);

/// A 40 x 40 Lambertian plane of reflectance `albedo` at z = -5 facing +z (two triangles,
/// material "white"): lit-plane oracles, where a pixel looking straight at it sees albedo / pi
/// x the irradiance a light gives it.
Scene lit_plane(float albedo, const std::string& source);

/// A closed axis-aligned box of 12 triangles (many rays hit its edges exactly).
Scene closed_box(Vec3 lo, Vec3 hi);

/// n rays from points in [-0.5, 1.5]^3 towards points in the unit cube; some with
/// axis-parallel directions (exact zeros), some with finite tmax, some with tmin > 0.
std::vector<Ray> random_rays(size_t n, uint64_t seed);

/// build_accel with this builder and layout, the rest default.
Accel build_layout(const Scene& scene, Builder builder, Layout layout);

/// A float's bits (for tests that ask for the same value bit for bit).
uint32_t float_bits(float f);

/// Path of a shared scene (../shared/scenes/REL), or nullopt when the folder is absent.
std::optional<std::string> shared_scene(const std::string& rel);

/// Every triangle by global id plus validity, for brute force.
struct Soup {
  Buffer<Triangle> triangles;
  std::vector<uint8_t> valid;
};
Soup flatten(const Scene& scene);

/// The kernel instruction sets this CPU runs (sse2 always).
std::vector<Isa> supported_isas();

/// Every builder, for parameterised tests.
std::vector<Builder> all_builders();

/// Standard base64 (RFC 4648, with padding): glTF data URIs of the test files.
std::string base64(const std::string& bytes);

/// A synthetic animated glTF (written under the test temp dir; its path returned), so the
/// two-level tests never depend on ../shared/scenes: mesh 0 a closed box placed by node 0
/// and by its child node 1 (translated by +3 x), mesh 1 a 60-triangle soup with one morph
/// target (every vertex +0.3 y) placed by node 2; one clip of 2 s: node 0 translates
/// LINEARly from (0, 0, 0) to (0, 1, 0), node 2's morph weight goes from 0 to 1.
std::string write_animated_gltf(const std::string& name);

/// This process's directory for test files (kestrel_tests_<pid> under the system's temp
/// dir, created; removed at exit): test runs side by side (two clones, two ctest invocations)
/// never share files.
std::filesystem::path test_temp_dir();

/// Writes text to a fresh file under the test temp dir and returns its path.
std::string write_temp_file(const std::string& name, const std::string& contents);

/// Pearson's chi-square of observed against expected counts (one entry per cell), the cells
/// expected below 5 pooled into one (a cell itself when its expectation reaches 5): the
/// p-value (Wilson-Hilferty's approximation), the statistic, the cells counted, and the pooled
/// cells' observed count and expectation.
struct ChiSquare {
  double p = 1, chi2 = 0;
  int cells = 0;
  double pool_observed = 0, pool_expected = 0;
};
ChiSquare chi_square(const std::vector<double>& expected, const std::vector<double>& observed);

/// An output against a framework's (PyTorch's) expected image of the same size: the worst
/// error relative to |expected| + 0.01, and the PSNR (peak 1). Sizes that differ are a test
/// failure (and a worst of +inf, a PSNR of -inf).
struct ImageMatch {
  double worst = 0, psnr = 0;
};
ImageMatch match_images(const FloatImage& out, const FloatImage& expected);

}  // namespace kestrel::test
