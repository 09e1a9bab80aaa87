#include "fuzz_driver.h"
#include "kestrel/io.h"

const char* const kestrel::fuzz::input_name = "fuzz.rays";

void kestrel::fuzz::fuzz_one(const std::string& path, const std::string&) {
  (void)read_rays(path);
}
