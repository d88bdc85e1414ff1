#!/usr/bin/env bash
# Sets everything up and runs the demo: installs missing Debian packages, builds the pbrlod tool,
# renders the generated demo scene and the Stanford bunny, and writes PNGs to out/.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$root"
bash scripts/install-deps.sh
jobs="${JOBS:-$(nproc)}"
# The same build tree and generator as test.sh (Ninja; ccache when installed), so running one
# script after the other reuses the build.
launcher=()
if [ "${PBR_LOD_CCACHE:-1}" != 0 ] && command -v ccache > /dev/null; then
  launcher=(-DCMAKE_CXX_COMPILER_LAUNCHER=ccache)
  export CCACHE_BASEDIR="$root" CCACHE_NOHASHDIR=1
fi
cmake -S . -B build/release -G Ninja -DCMAKE_BUILD_TYPE=Release "${launcher[@]}"
cmake --build build/release -j "$jobs" --target pbrlod
mkdir -p out
./build/release/examples/pbrlod demo -o out/demo
data="${PBR_LOD_DATA:-$root/../shared/data}"
if [ -f "$data/bun_zipper.ply" ]; then
  ./build/release/examples/pbrlod demo "$data/bun_zipper.ply" -o out/bunny
else
  echo "demo.sh: $data/bun_zipper.ply not found; skipped the bunny (set PBR_LOD_DATA)" >&2
fi
echo "demo.sh: images are in $root/out/"
