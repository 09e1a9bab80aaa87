// glTF 2.0, loaded both ways: flattened, and as an animated two-level scene posed inside its
// clip. Built twice: as fuzz_gltf (JSON, .gltf) and, with KESTREL_FUZZ_GLB, fuzz_glb (binary).
#include "fuzz_driver.h"
#include "kestrel/instances.h"
#include "kestrel/scene.h"

#ifdef KESTREL_FUZZ_GLB
const char* const kestrel::fuzz::input_name = "fuzz.glb";
#else
const char* const kestrel::fuzz::input_name = "fuzz.gltf";
#endif

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
