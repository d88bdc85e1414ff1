#!/usr/bin/env bash
# Sets everything up and runs the demo: installs missing Debian packages, builds the pbrlod tool,
# renders the generated demo scene and the Stanford bunny, and writes PNGs to out/.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$root"
bash scripts/install-deps.sh
# The same build tree, generator and flags as test.sh (scripts/configure.sh), so running one
# script after the other reuses the build.
# shellcheck source=scripts/configure.sh
source scripts/configure.sh
configure_release
cmake --build "$build/release" -j "$jobs" --target pbrlod
mkdir -p out
"./$build/release/examples/pbrlod" demo -o out/demo
if [ -f "$data/bun_zipper.ply" ]; then
  "./$build/release/examples/pbrlod" demo "$data/bun_zipper.ply" -o out/bunny
else
  echo "demo.sh: $data/bun_zipper.ply not found; skipped the bunny (set PBR_LOD_DATA)" >&2
fi
echo "demo.sh: images are in $root/out/"
