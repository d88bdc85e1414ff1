#!/usr/bin/env bash
# Sets everything up and runs every test: installs missing Debian packages, builds pbr_lod with
# warnings as errors, runs the test suite (which also installs the library to a temporary prefix
# and builds a consumer project against it), then builds and runs the suite again under
# AddressSanitizer + UndefinedBehaviorSanitizer.
#
# Environment: PBR_LOD_DATA (the shared/data folder; default ../shared/data beside the checkout),
# JOBS (parallel build jobs; default: number of cores), SKIP_SANITIZERS=1 to skip the second pass.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$root"
bash scripts/install-deps.sh
jobs="${JOBS:-$(nproc)}"
data="${PBR_LOD_DATA:-$root/../shared/data}"
if [ ! -f "$data/bun_zipper.ply" ]; then
  echo "test.sh: the shared data folder is missing: $data (set PBR_LOD_DATA)" >&2
  exit 1
fi
export PBR_LOD_DATA="$data"

echo "== build (Release, -Werror)"
cmake -S . -B build/release -DCMAKE_BUILD_TYPE=Release -DPBR_LOD_WERROR=ON -DPBR_LOD_DATA_DIR="$data"
cmake --build build/release -j "$jobs"
echo "== tests (Release)"
ctest --test-dir build/release --output-on-failure -j "$jobs"

if [ "${SKIP_SANITIZERS:-0}" != 1 ]; then
  echo "== build (AddressSanitizer + UndefinedBehaviorSanitizer)"
  cmake -S . -B build/asan -DCMAKE_BUILD_TYPE=RelWithDebInfo -DPBR_LOD_SANITIZE=ON \
    -DPBR_LOD_WERROR=ON -DPBR_LOD_BUILD_BENCHMARKS=OFF -DPBR_LOD_DATA_DIR="$data"
  cmake --build build/asan -j "$jobs"
  echo "== tests (sanitizers)"
  ASAN_OPTIONS=detect_leaks=1:abort_on_error=1 UBSAN_OPTIONS=print_stacktrace=1:halt_on_error=1 \
    ctest --test-dir build/asan --output-on-failure -j "$jobs"
fi
