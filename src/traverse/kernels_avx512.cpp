// The wide-BVH kernels compiled for avx512 (flags set per file in CMakeLists.txt).
#define KESTREL_ISA_NS avx512
#include "traverse/wide_kernels.inl"

namespace kestrel::kernels {
const Table& table_avx512() {
  return avx512::table;
}
}  // namespace kestrel::kernels
