// kestrel public API: the instruction sets kestrel's kernels are compiled for, and the one
// choice every module follows (traversal, denoiser, upsampler): default_isa().
#pragma once
#include <optional>
#include <string>

namespace kestrel {

/// Instruction sets with kernels (traversal, convolution, reconstruction). sse2 is the x86-64
/// baseline (always there); avx2 needs AVX2+FMA+BMI; avx512 needs AVX-512 F/VL/BW/DQ.
enum class Isa { sse2, avx2, avx512 };
const char* isa_name(Isa isa);
/// Parses "sse2", "avx2", "avx512".
std::optional<Isa> isa_from_name(const std::string& name);
/// Whether this CPU (and OS) runs the ISA.
bool isa_supported(Isa isa);
/// Throws Error(invalid_argument) naming the ISA and this CPU's best unless it runs here.
void require_supported(Isa isa);
/// The best ISA of this CPU.
Isa host_isa();
/// The ISA used when TraceOptions leaves it open: host_isa(), or the KESTREL_ISA
/// environment variable, or what set_default_isa chose. Throws if unsupported.
Isa default_isa();
void set_default_isa(Isa isa);

}  // namespace kestrel
