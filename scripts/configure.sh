#!/usr/bin/env bash
# Configures the release build tree the same way for scripts/demo.sh and scripts/test.sh, so
# that whichever runs second reuses the first one's objects (the same compiler flags: -Werror,
# the data folder, ccache as the launcher). Sourced, not run: sets `build`, `data`, `jobs` and
# `common` (the flags every build tree of test.sh also gets).
#
# Environment: PBR_LOD_DATA (default ../shared/data beside the checkout), BUILD_DIR (default
# build), JOBS (default: number of cores), PBR_LOD_CCACHE=0 to build without ccache.
# Canonical (no "..") so that every clone beside the data compiles the tests with the same
# define, and ccache serves one clone's objects to the next.
data="$(realpath -m "${PBR_LOD_DATA:-$root/../shared/data}")"
build="${BUILD_DIR:-build}"
jobs="${JOBS:-$(nproc)}"
common=(-G Ninja -DPBR_LOD_WERROR=ON -DPBR_LOD_DATA_DIR="$data")
if [ "${PBR_LOD_CCACHE:-1}" != 0 ] && command -v ccache > /dev/null; then
  common+=(-DCMAKE_CXX_COMPILER_LAUNCHER=ccache)
  export CCACHE_BASEDIR="$root" CCACHE_NOHASHDIR=1
fi
configure_release() {
  cmake -S . -B "$build/release" "${common[@]}" -DCMAKE_BUILD_TYPE=Release
}
