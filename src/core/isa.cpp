// Instruction-set detection and the process-wide choice (kestrel/isa.h): one mechanism for
// every module with per-ISA kernels.
#include "kestrel/isa.h"

#include <fmt/format.h>

#include <atomic>
#include <cstdlib>

#include "kestrel/error.h"

namespace kestrel {

const char* isa_name(Isa isa) {
  switch (isa) {
    case Isa::sse2:
      return "sse2";
    case Isa::avx2:
      return "avx2";
    case Isa::avx512:
      return "avx512";
  }
  return "?";
}

std::optional<Isa> isa_from_name(const std::string& name) {
  if (name == "sse2") return Isa::sse2;
  if (name == "avx2") return Isa::avx2;
  if (name == "avx512") return Isa::avx512;
  return std::nullopt;
}

bool isa_supported(Isa isa) {
  // libgcc's CPU model checks CPUID and that the OS saves the wider registers (XGETBV).
  __builtin_cpu_init();
  switch (isa) {
    case Isa::sse2:
      return true;
    case Isa::avx2:
      return __builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma") &&
             __builtin_cpu_supports("bmi") && __builtin_cpu_supports("bmi2") &&
             __builtin_cpu_supports("popcnt");
    case Isa::avx512:
      return isa_supported(Isa::avx2) && __builtin_cpu_supports("avx512f") &&
             __builtin_cpu_supports("avx512vl") && __builtin_cpu_supports("avx512bw") &&
             __builtin_cpu_supports("avx512dq");
  }
  return false;
}

Isa host_isa() {
  static const Isa best = isa_supported(Isa::avx512) ? Isa::avx512
                          : isa_supported(Isa::avx2) ? Isa::avx2
                                                     : Isa::sse2;
  return best;
}

namespace {
std::atomic<int> g_default_isa{-1};
}  // namespace

void require_supported(Isa isa) {
  if (!isa_supported(isa))
    throw Error(ErrorCode::invalid_argument,
                fmt::format("ISA '{}' is not supported by this CPU (best: {})", isa_name(isa),
                            isa_name(host_isa())));
}

Isa default_isa() {
  int v = g_default_isa.load(std::memory_order_relaxed);
  if (v < 0) {
    Isa isa = host_isa();
    if (const char* env = std::getenv("KESTREL_ISA"); env && *env) {
      auto parsed = isa_from_name(env);
      if (!parsed)
        throw Error(ErrorCode::invalid_argument,
                    fmt::format("KESTREL_ISA='{}': expected sse2, avx2 or avx512", env));
      require_supported(*parsed);
      isa = *parsed;
    }
    v = int(isa);
    g_default_isa.store(v, std::memory_order_relaxed);
  }
  return Isa(v);
}

void set_default_isa(Isa isa) {
  require_supported(isa);
  g_default_isa.store(int(isa), std::memory_order_relaxed);
}

}  // namespace kestrel
