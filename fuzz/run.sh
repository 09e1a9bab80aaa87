#!/usr/bin/env bash
# Builds kestrel's libFuzzer harnesses (clang-14; ASan + UBSan) and runs each for SECONDS
# (default 30), or with KESTREL_FUZZ_CI=1 a fixed number of inputs from a fixed seed (what CI
# runs: the same inputs every time, about 10 s each here, SECONDS as a cap), from its seed corpus (fuzz/corpus/NAME) and regression inputs
# (fuzz/regressions/NAME), with a 2 GiB memory limit and a 10 s per-input time-out. Writes a
# table of executions and coverage to build/fuzz/report.md. Exits non-zero on any finding: its
# input is saved as build/fuzz/findings/NAME-*; copy it into fuzz/regressions/NAME/ with the fix.
#   bash fuzz/run.sh [SECONDS] [NAME ...]
set -euo pipefail
seconds=${1:-30}
shift || true
here=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
build=${KESTREL_FUZZ_BUILD:-$here/build/fuzz}
names=("$@")
[ ${#names[@]} -gt 0 ] || names=(obj gltf glb pfm exr image rays hits weights camera_path views instances)
command -v clang++-14 >/dev/null || { echo "fuzz: clang++-14 is missing (apt-get install clang-14 libclang-rt-14-dev)"; exit 1; }
launcher=()
command -v ccache >/dev/null && launcher=(-DCMAKE_CXX_COMPILER_LAUNCHER=ccache)
cmake -S "$here" -B "$build" -G Ninja -DCMAKE_CXX_COMPILER=clang++-14 -DCMAKE_BUILD_TYPE=RelWithDebInfo \
  -DKESTREL_FUZZ=ON -DKESTREL_SANITIZE=ON -DKESTREL_BUILD_TESTS=OFF -DKESTREL_WITH_PYTHON=OFF -DKESTREL_WITH_MPI=OFF \
  -DKESTREL_WITH_EMBREE=OFF "${launcher[@]}" > "$build.configure.log" 2>&1 || { cat "$build.configure.log"; exit 1; }
cmake --build "$build" --target kestrel_fuzzers -j "$(nproc)" > "$build/build.log" 2>&1 || { tail -40 "$build/build.log"; exit 1; }
export ASAN_OPTIONS=detect_leaks=0:abort_on_error=1:allocator_may_return_null=1
export UBSAN_OPTIONS=print_stacktrace=1:halt_on_error=1
mkdir -p "$build/findings"
report="$build/report.md"
{
  echo "| harness | seconds | executions | exec/s | coverage (edges) | features | corpus | result |"
  echo "|---|---:|---:|---:|---:|---:|---:|---|"
} > "$report"
# Inputs per harness for KESTREL_FUZZ_CI: about 10 s each under ASan on this machine.
declare -A ci_runs=([obj]=80000 [gltf]=40000 [glb]=60000 [pfm]=300000 [exr]=400 [image]=20000 [rays]=250000
  [hits]=250000 [weights]=30000 [camera_path]=150000 [views]=150000 [instances]=150000)
status=0
ok_count=0
for name in "${names[@]}"; do
  work="$build/corpus/$name"
  mkdir -p "$work" "$here/fuzz/regressions/$name"
  log="$build/$name.log"
  mode=()
  if [ -n "${KESTREL_FUZZ_CI:-}" ]; then
    rm -rf "$work" && mkdir -p "$work"  # the same start every time
    mode=(-seed=1 -runs="${ci_runs[$name]:-20000}")
  fi
  set +e
  "$build/fuzz/fuzz_$name" "${mode[@]}" -max_total_time="$seconds" -rss_limit_mb=2048 -malloc_limit_mb=2048 -timeout=10 \
    -print_final_stats=1 -artifact_prefix="$build/findings/$name-" "$work" "$here/fuzz/corpus/$name" \
    "$here/fuzz/regressions/$name" > "$log" 2>&1
  code=$?
  set -e
  execs=$(grep -o "stat::number_of_executed_units: *[0-9]*" "$log" | grep -o "[0-9]*$" | tail -1)
  rate=$(grep -o "stat::average_exec_per_sec: *[0-9]*" "$log" | grep -o "[0-9]*$" | tail -1)
  last=$(grep -E "^#[0-9]+" "$log" | tail -1)
  cov=$(echo "$last" | grep -o "cov: [0-9]*" | grep -o "[0-9]*")
  ft=$(echo "$last" | grep -o "ft: [0-9]*" | grep -o "[0-9]*")
  corp=$(echo "$last" | grep -o "corp: [0-9]*" | grep -o "[0-9]*")
  result=ok
  if [ "$code" -ne 0 ]; then
    result="**FINDING** (exit $code)"
    status=1
    echo "== fuzz_$name found a problem:"
    grep -E "ERROR|SUMMARY|fuzz:|==[0-9]+==|Test unit written" "$log" | head -20
  fi
  [ "$result" = ok ] && ok_count=$((ok_count + 1))
  echo "| $name | $seconds | ${execs:-?} | ${rate:-?} | ${cov:-?} | ${ft:-?} | ${corp:-?} | $result |" >> "$report"
done
cat "$report"
echo "fuzz: $ok_count passed, $(( ${#names[@]} - ok_count )) failed"
exit $status
