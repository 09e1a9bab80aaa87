// Procedural built-in scenes (builtin:soup, hairball, terrain, sphere_field): geometry the
// shared scenes lack, for the benchmarks and tests.
#pragma once
#include <optional>
#include <string>
#include <vector>

#include "kestrel/scene.h"

namespace kestrel {

std::vector<std::string> procedural_scene_names();
/// The scene of that name, or nullopt for a name that is not one of them.
std::optional<Scene> make_procedural_scene(const std::string& name);

}  // namespace kestrel
