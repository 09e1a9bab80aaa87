// Binary glTF (.glb), flattened and as an animated two-level scene.
#include "fuzz_driver.h"
#include "kestrel/instances.h"
#include "kestrel/scene.h"

const char* const kestrel::fuzz::input_name = "fuzz.glb";

void kestrel::fuzz::fuzz_one(const std::string& path, const std::string&) {
  try {
    (void)load_scene(path);
  } catch (const Error&) {
  }
  GltfInstances g = GltfInstances::load(path);
  InstancedScene scene;
  g.add_to(scene);
  g.set_time(scene, 0.5);
  scene.commit();
}
