// The `kestrel` CLI's subcommands: each registers its options and returns the action to run.
#pragma once
#include <CLI/CLI.hpp>
#include <functional>
#include <string>

#include "common/views.h"
#include "kestrel/asset.h"
#include "kestrel/bvh.h"
#include "kestrel/io.h"
#include "kestrel/render.h"

namespace kestrel::cli {

using Action = std::function<void()>;

Action add_bvh_command(CLI::App& app);
Action add_trace_command(CLI::App& app);
Action add_rays_command(CLI::App& app);
Action add_preview_command(CLI::App& app);
Action add_render_command(CLI::App& app);
Action add_render_sequence_command(CLI::App& app);
Action add_denoise_command(CLI::App& app);
Action add_upscale_command(CLI::App& app);
Action add_run_command(CLI::App& app);
Action add_view_command(CLI::App& app);

/// "name_%04d.pfm" with frame 7 -> "name_0007.pfm"; exactly one %d / %0Nd, else Error.
std::string frame_name(const std::string& pattern, int frame);
/// Writes a 3-channel image as .exr or .pfm (by extension; parent directories created).
void write_image(const std::string& path, const FloatImage& img);

/// Options shared by the commands that build a BVH.
struct BuildOptions {
  std::string builder;
  std::string quality = "balanced";
  float traversal_cost = 1.0f, intersection_cost = 1.0f;
  uint32_t max_leaf_size = 8, bin_count = 32, morton_bits = 30;
  int threads = 0;
  double expected_rays = 1e6;
  void add_to(CLI::App& cmd);
  BuildConfig config() const;  ///< throws Error on an unknown builder/quality
};

using tools::camera_path_for;
using tools::start_camera_for;

/// Parses "WxH" into positive width and height; throws Error otherwise.
void parse_resolution(const std::string& text, int& width, int& height);
/// load_scene, with the scene's warnings (skipped triangles, missing textures) on stderr.
Scene load_scene_reporting(const std::string& path);
/// Asset::load, its warnings printed to stderr (rank 0 only under mpirun).
Asset load_asset_reporting(const std::string& path);

}  // namespace kestrel::cli
