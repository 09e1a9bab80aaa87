// The `kestrel` CLI's subcommands: each registers its options and returns the action to run.
#pragma once
#include <CLI/CLI.hpp>
#include <functional>
#include <string>

#include "kestrel/bvh.h"

namespace kestrel::cli {

using Action = std::function<void()>;

Action add_bvh_command(CLI::App& app);
Action add_trace_command(CLI::App& app);
Action add_rays_command(CLI::App& app);
Action add_preview_command(CLI::App& app);
Action add_render_command(CLI::App& app);
Action add_render_sequence_command(CLI::App& app);
Action add_denoise_command(CLI::App& app);

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

/// Parses "WxH" into positive width and height; throws Error otherwise.
void parse_resolution(const std::string& text, int& width, int& height);

}  // namespace kestrel::cli
