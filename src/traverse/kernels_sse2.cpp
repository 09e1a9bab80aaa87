// The wide-BVH kernels compiled for sse2 (flags set per file in CMakeLists.txt).
#define KESTREL_ISA_NS sse2
#include "traverse/wide_kernels.inl"

namespace kestrel::kernels {
const Table& table_sse2() {
  return sse2::table;
}
}  // namespace kestrel::kernels
