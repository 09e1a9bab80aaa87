// Named views (JSON).
#include "fuzz_driver.h"
#include "kestrel/render.h"

const char* const kestrel::fuzz::input_name = "fuzz.views.json";

void kestrel::fuzz::fuzz_one(const std::string& path, const std::string&) {
  for (const auto& [name, camera] : load_views(path)) check_camera(camera);
}
