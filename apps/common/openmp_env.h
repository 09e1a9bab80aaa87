// OpenMP's threads made to sleep between oneDNN's parallel regions in kestrel's programs.
#pragma once

namespace kestrel::cli {

/// Debian's oneDNN (the rae denoiser, the nsrr and nsrr-rt upsamplers) runs on libgomp's
/// threads beside kestrel's own pool. By default libgomp keeps them spinning for a while after
/// each parallel region, and on a machine with few cores they take the CPU from the steps that
/// run in between (nsrr-rt to 1280x720 on two threads: 42.9 / 43.1 ms a frame against 40.0 /
/// 37.8 passive; docs/upscaler.md). libgomp reads OMP_WAIT_POLICY once, as it loads, before
/// main — and glibc resets the environment after an executable's preinit functions — so a
/// program that will run those networks sets the variable and executes itself again, first
/// thing in main (once: the second time the variable is set). Nothing happens when the user
/// set OMP_WAIT_POLICY, when `always` is false and no argument names rae, nsrr or nsrr-rt (as
/// a word or after '='), or when /proc/self/exe cannot be executed (the run goes on as is).
void passive_openmp_for_onednn(int argc, char** argv, bool always = false);

}  // namespace kestrel::cli
