// OBJ + MTL: the input is the OBJ; everything after a line "#MTL" is also written as the
// material library "fuzz.mtl" beside it (seeds name it with `mtllib fuzz.mtl`).
#include "fuzz_driver.h"
#include "kestrel/scene.h"

const char* const kestrel::fuzz::input_name = "fuzz.obj";

void kestrel::fuzz::fuzz_one(const std::string& path, const std::string& bytes) {
  const size_t split = bytes.find("\n#MTL\n");
  write_file(scratch_dir() + "/fuzz.mtl",
             split == std::string::npos ? std::string() : bytes.substr(split + 6));
  const Scene scene = load_scene(path);
  (void)validate_scene(scene);
}
