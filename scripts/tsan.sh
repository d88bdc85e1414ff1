#!/usr/bin/env bash
# The hierarchies' concurrency promises under ThreadSanitizer: several threads traversing one
# loaded hierarchy of each builder (Ladder's ConcurrentTraversal), a chunked hierarchy loading
# its chunks lazily from several threads, and the thread-parallel builds and k-NN queries the
# tests run anyway (the ladder builds every builder on two threads), and the streaming point
# sources read from several threads. Builds the `tsan` preset (build/tsan: the library and four
# test programs) and runs those tests; scripts/test.sh runs it
# after the ASan pass (docs/development.md). The library's task runner is plain std::threads
# there (src/core/parallel_threads.cpp): TSan cannot see inside Debian's uninstrumented oneTBB.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$root"
jobs="${JOBS:-$(nproc)}"
launcher=()
if [ "${PBR_LOD_CCACHE:-1}" != 0 ] && command -v ccache > /dev/null; then
  launcher=(-DCMAKE_CXX_COMPILER_LAUNCHER=ccache)
  export CCACHE_BASEDIR="$root" CCACHE_NOHASHDIR=1
fi
data="${PBR_LOD_DATA:-$root/../shared/data}"
cmake --preset tsan "${launcher[@]}" -DPBR_LOD_DATA_DIR="$data"
cmake --build build/tsan -j "$jobs" --target test_ladder test_point_octree test_core test_io
# halt_on_error: the first race fails the run; second_deadlock_stack for readable lock reports.
export TSAN_OPTIONS="halt_on_error=1 second_deadlock_stack=1"
export PBR_LOD_DATA="$data"
# Each filter must select tests: a renamed suite would otherwise pass here by running nothing.
run() {  # run PROGRAM FILTER
  local out
  out="$(mktemp)"
  "$1" --gtest_filter="$2" 2>&1 | tee "$out"
  if ! grep -qE '^\[  PASSED  \] [1-9][0-9]* test' "$out"; then
    echo "tsan.sh: $1 --gtest_filter='$2' ran no test" >&2
    rm -f "$out"
    exit 1
  fi
  rm -f "$out"
}
run build/tsan/tests/builders/test_ladder 'AllBuilders/ConcurrentTraversal.*'
run build/tsan/tests/builders/test_point_octree 'ChunkedPointOctree.*:ChunkedPointOctree/ChunkedLayer/*'
run build/tsan/tests/core/test_core 'Parallel*:*Knn*:*Estimat*'
# The streaming point sources read from several threads (the ASCII file resumes where a read
# ended, under a mutex; 30 s here); the LAZ chunk cache.
run build/tsan/tests/io/test_io 'Source.ConcurrentReads:LazTwins.PointSourceGivesWhatReadPointsGives'
echo "tsan.sh: no data races reported"
