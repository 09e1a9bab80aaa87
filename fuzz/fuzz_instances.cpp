// Instance files (one "sx sy sz tx ty tz rot_y" per line), placed in a two-level scene.
#include "fuzz_driver.h"
#include "kestrel/instances.h"

const char* const kestrel::fuzz::input_name = "fuzz.instances.txt";

void kestrel::fuzz::fuzz_one(const std::string& path, const std::string&) {
  const std::vector<Affine3> transforms = load_instance_transforms(path);
  InstancedScene scene;
  TriangleMesh m;
  m.positions = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}};
  m.indices = {0, 1, 2};
  m.material_ids = {0};
  const MeshId mesh = scene.add_mesh(m);
  for (size_t i = 0; i < transforms.size() && i < 4096; ++i)
    scene.add_instance(mesh, transforms[i]);
  scene.commit();
}
