// glTF 2.0 JSON (.gltf), loaded both ways: flattened and as an animated two-level scene.
#include "fuzz_driver.h"
#include "kestrel/instances.h"
#include "kestrel/scene.h"

const char* const kestrel::fuzz::input_name = "fuzz.gltf";

void kestrel::fuzz::fuzz_one(const std::string& path, const std::string&) {
  try {
    (void)load_scene(path);
  } catch (const Error&) {
  }
  GltfInstances g = GltfInstances::load(path);
  InstancedScene scene;
  g.add_to(scene);
  g.set_time(scene, 0.37 * (g.duration() > 0 ? g.duration() : 1.0));
  scene.commit();
}
