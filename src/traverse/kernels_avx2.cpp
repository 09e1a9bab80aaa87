// The wide-BVH kernels compiled for avx2 (flags set per file in CMakeLists.txt).
#define KESTREL_ISA_NS avx2
#include "traverse/wide_kernels.inl"

namespace kestrel::kernels {
const Table& table_avx2() {
  return avx2::table;
}
}  // namespace kestrel::kernels
