#!/usr/bin/env bash
# Sets everything up and runs every test: installs missing Debian packages, builds pbr_lod with
# warnings as errors, runs the test suite (which also installs the library to a temporary prefix
# and builds a consumer project against it), then builds and runs the suite again under
# AddressSanitizer + UndefinedBehaviorSanitizer (but the end-to-end measurements of
# tests/release_only.txt), then the concurrency tests under ThreadSanitizer (scripts/tsan.sh), then
# runs every fuzz target briefly (scripts/fuzz.sh, docs/fuzzing.md).
#
# Environment: PBR_LOD_DATA (the shared/data folder; default ../shared/data beside the checkout;
# when it is missing, tests that read the real scans are skipped, unless CI=true, which fails),
# JOBS (parallel build jobs; default: number of cores), SKIP_SANITIZERS=1 to skip the second pass,
# SKIP_TSAN=1 to skip the ThreadSanitizer pass,
# FUZZ_SECONDS (per fuzz target; default 10; 0 skips the fuzz pass),
# BUILD_DIR (default: build), PBR_LOD_CCACHE=0 to build without ccache.
#
# Build cost (docs/development.md): Ninja, and ccache as the compiler launcher when it is
# installed (install-deps.sh installs it), so a second run recompiles only what changed. The
# sanitizer pass compiles at -O1 -g1, the optimisation level AddressSanitizer is meant for: at
# -O2 -g the sanitizer build took 60 of CI's 77 minutes and found nothing -O1 misses.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$root"
start=$SECONDS
phase_start=$SECONDS
phase() {  # phase NAME — prints how long the previous phase took, then starts the next
  local now=$SECONDS
  [ -n "${phase_name:-}" ] && printf 'test.sh: phase %-28s %4d s\n' "$phase_name" $((now - phase_start))
  phase_name="$1"
  phase_start=$now
  [ -n "$1" ] && echo "== $1"
  return 0
}
phase "install dependencies"
bash scripts/install-deps.sh --peers  # with PCL, for the sweep's PCL peers
# shellcheck source=scripts/configure.sh
source scripts/configure.sh  # build, data, jobs, common: the same as scripts/demo.sh
if [ ! -f "$data/bun_zipper.ply" ]; then
  if [ "${CI:-}" = "true" ]; then
    echo "test.sh: the shared data folder is missing: $data (set PBR_LOD_DATA); CI runs every test" >&2
    exit 1
  fi
  echo "test.sh: the shared data folder is missing: $data" >&2
  echo "test.sh: tests that read the real scans are skipped; everything on generated data runs." >&2
  echo "test.sh: to run them all: PBR_LOD_DATA=/path/to/shared/data bash scripts/test.sh" >&2
fi
export PBR_LOD_DATA="$data"
[ "${PBR_LOD_CCACHE:-1}" != 0 ] && command -v ccache > /dev/null && { ccache -z > /dev/null || true; }

phase "build (Release, -Werror)"
configure_release
cmake --build "$build/release" -j "$jobs"
phase "tests (Release)"
ctest --test-dir "$build/release" --output-on-failure -j "$jobs"

if [ "${SKIP_SANITIZERS:-0}" != 1 ]; then
  phase "build (ASan + UBSan)"
  cmake -S . -B "$build/asan" "${common[@]}" -DCMAKE_BUILD_TYPE=RelWithDebInfo \
    -DCMAKE_CXX_FLAGS_RELWITHDEBINFO="-O1 -g1 -DNDEBUG" -DPBR_LOD_SANITIZE=ON \
    -DPBR_LOD_BUILD_BENCHMARKS=OFF
  cmake --build "$build/asan" -j "$jobs"
  phase "tests (ASan + UBSan)"
  # tests/release_only.txt: end-to-end measurements the Release pass runs and this one need not.
  mapfile -t release_only < <(sed -e 's/#.*//' -e '/^ *$/d' tests/release_only.txt)
  count='1'  # a renamed test must not leave a stale line behind; without the scans, some are absent
  [ -f "$data/bun_zipper.ply" ] || count='[01]'
  for t in "${release_only[@]}"; do
    ctest --test-dir "$build/asan" -N -R "^$t\$" | grep -q "^Total Tests: $count\$" ||
      { echo "test.sh: tests/release_only.txt: '$t' names no single test" >&2; exit 1; }
  done
  release_only="^($(IFS='|'; echo "${release_only[*]}"))\$"
  ASAN_OPTIONS=detect_leaks=1:abort_on_error=1 UBSAN_OPTIONS=print_stacktrace=1:halt_on_error=1 \
    ctest --test-dir "$build/asan" --output-on-failure -j "$jobs" -E "$release_only"
fi
if [ "${SKIP_TSAN:-0}" != 1 ]; then
  phase "build + tests (ThreadSanitizer)"
  JOBS="$jobs" bash scripts/tsan.sh  # the concurrency promises: docs/development.md
fi
fuzz_seconds="${FUZZ_SECONDS:-10}"
if [ "$fuzz_seconds" != 0 ]; then
  # install-deps.sh installs clang-16; a machine that cannot have it still runs everything else.
  if command -v clang++-16 > /dev/null; then
    phase "fuzz (${fuzz_seconds} s per target)"
    PBRLOD="$(realpath "$build/release/examples/pbrlod")" JOBS="$jobs" \
      bash scripts/fuzz.sh "$fuzz_seconds"
  else
    echo "test.sh: clang++-16 is missing; skipped the fuzz pass (bash scripts/install-deps.sh)" >&2
  fi
fi
phase ""
command -v ccache > /dev/null && [ "${PBR_LOD_CCACHE:-1}" != 0 ] &&
  ccache -s 2> /dev/null | grep -iE '^ *(hits|misses)|cacheable' | sed 's/^/test.sh: ccache /' || true
printf 'test.sh: all phases %d s\n' $((SECONDS - start))
