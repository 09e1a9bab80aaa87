// Keyframed camera paths (JSON), sampled along their span.
#include "fuzz_driver.h"
#include "kestrel/render.h"

const char* const kestrel::fuzz::input_name = "fuzz_path.json";

void kestrel::fuzz::fuzz_one(const std::string& path, const std::string&) {
  const CameraPath p = CameraPath::load(path);
  for (int i = 0; i <= 8; ++i) check_camera(p.at(p.start() + (p.end() - p.start()) * i / 8.0));
}
