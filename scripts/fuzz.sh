#!/usr/bin/env bash
# Builds the libFuzzer targets (the `fuzz` CMake preset: clang 16, ASan + UBSan, build/fuzz),
# writes their seed corpora from the shared data into build/fuzz/corpus/<target>/, and runs each
# target for a while. Any crash, leak, sanitizer report or timeout fails the script; libFuzzer
# writes the input that caused it to build/fuzz/artifacts/<target>/. docs/fuzzing.md.
#
#   scripts/fuzz.sh [SECONDS] [TARGET...]   SECONDS per target (default 10); TARGET: fuzz_ply, ...
#
# Environment: PBR_LOD_DATA (the shared/data folder; default ../shared/data beside the checkout),
# PBRLOD (a built pbrlod tool for the hierarchy seeds; default build/release/examples/pbrlod,
# built with the normal GCC tree when missing), JOBS (parallel build jobs; default: cores),
# PBR_LOD_CCACHE=0 to build without ccache, FUZZ_MAX_LEN (largest input in bytes; default 262144,
# which every seed fits; long runs go several times faster at 4096, where the small seeds still
# reach every parser and the large ones are cut short: docs/fuzzing.md), FUZZ_RUNS (stop each
# target after this many executions instead of after SECONDS; for campaigns with a count to reach),
# FUZZ_ASAN_OPTIONS (appended to ASAN_OPTIONS; campaigns use detect_stack_use_after_return=0,
# 1.9x as many executions per second: docs/fuzzing.md), FUZZ_TIMEOUT (seconds of wall time one
# input may take; default 10).
# The corpus folders keep what the fuzzer adds, so a second run starts where the first stopped.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$root"
seconds="${1:-10}"
shift $(($# > 0 ? 1 : 0))
source scripts/fuzz_targets.sh
targets=("${@:-${fuzz_targets[@]}}")
jobs="${JOBS:-$(nproc)}"
data="${PBR_LOD_DATA:-$root/../shared/data}"
build=build/fuzz

launcher=()
if [ "${PBR_LOD_CCACHE:-1}" != 0 ] && command -v ccache > /dev/null; then
  launcher=(-DCMAKE_CXX_COMPILER_LAUNCHER=ccache)
  export CCACHE_BASEDIR="$root" CCACHE_NOHASHDIR=1
fi
cmake --preset fuzz "${launcher[@]}" > /dev/null
cmake --build "$build" -j "$jobs" --target "${targets[@]}" make_laz_seeds

pbrlod="${PBRLOD:-$root/build/release/examples/pbrlod}"
if [ ! -x "$pbrlod" ]; then
  cmake -S . -B build/release -G Ninja -DCMAKE_BUILD_TYPE=Release "${launcher[@]}" > /dev/null
  cmake --build build/release -j "$jobs" --target pbrlod
fi
bash fuzz/make_corpus.sh "$pbrlod" "$data" "$build/corpus" "$build/fuzz/make_laz_seeds"

# -max_len: by default the largest seed (the PMR file, ~140 kB) fits; larger inputs only slow the
# run.
# -timeout: a single input taking longer than 10 s is a hang (libFuzzer counts wall time, so a
# campaign at nice 19 beside other work takes more: fuzz_campaign.sh). -rss_limit_mb: a count in a file
# that makes a reader allocate gigabytes is a finding (read.hpp: counts are checked first).
failed=()
for t in "${targets[@]}"; do
  mkdir -p "$build/artifacts/$t"
  log="$build/artifacts/$t/last_run.log"
  limit=(-max_total_time="$seconds")
  [ -n "${FUZZ_RUNS:-}" ] && limit=(-runs="$FUZZ_RUNS")
  if ASAN_OPTIONS="detect_leaks=1${FUZZ_ASAN_OPTIONS:+:$FUZZ_ASAN_OPTIONS}" \
    UBSAN_OPTIONS=print_stacktrace=1:halt_on_error=1 \
    "$build/fuzz/$t" "$build/corpus/$t" "${limit[@]}" \
    -max_len="${FUZZ_MAX_LEN:-262144}" \
    -timeout="${FUZZ_TIMEOUT:-10}" -rss_limit_mb=2048 -print_final_stats=1 \
    -artifact_prefix="$build/artifacts/$t/" > "$log" 2>&1; then
    runs=$(sed -n 's/^stat::number_of_executed_units: *//p' "$log")
    rate=$(sed -n 's/^stat::average_exec_per_sec: *//p' "$log")
    printf 'fuzz.sh: %-24s %10s runs %7s exec/s  ok\n' "$t" "${runs:-?}" "${rate:-?}"
  else
    failed+=("$t")
    printf 'fuzz.sh: %-24s FAILED; input and log in %s\n' "$t" "$build/artifacts/$t/"
    grep -E 'ERROR|SUMMARY|terminate|Test unit written' "$log" | head -5 | sed 's/^/    /'
  fi
done
if [ ${#failed[@]} -ne 0 ]; then
  echo "fuzz.sh: ${#failed[@]} target(s) failed: ${failed[*]}" >&2
  exit 1
fi
