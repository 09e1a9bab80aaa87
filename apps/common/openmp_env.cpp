// See openmp_env.h.
#include "openmp_env.h"

#include <unistd.h>

#include <cstdlib>
#include <string_view>

namespace kestrel::cli {

namespace {

// Whether an argument names a network that runs on oneDNN: "rae", "nsrr", "nsrr-rt", alone
// or as the value of --option=VALUE.
bool names_onednn_network(std::string_view arg) {
  if (const size_t eq = arg.find('='); eq != std::string_view::npos) arg.remove_prefix(eq + 1);
  return arg == "rae" || arg == "nsrr" || arg == "nsrr-rt";
}

}  // namespace

void passive_openmp_for_onednn(int argc, char** argv, bool always) {
  if (std::getenv("OMP_WAIT_POLICY") != nullptr) return;
  bool wanted = always;
  for (int i = 1; i < argc && !wanted; ++i) wanted = names_onednn_network(argv[i]);
  if (!wanted) return;
  if (setenv("OMP_WAIT_POLICY", "PASSIVE", 0) != 0) return;
  execv("/proc/self/exe", argv);  // returns only on failure: go on with libgomp's default
}

}  // namespace kestrel::cli
