#!/usr/bin/env bash
# Installs what pbr_lod needs on Debian 12 (bookworm) from Debian's packages. Idempotent: it only
# calls apt-get when a package is missing. Uses sudo when not run as root.
#
#   install-deps.sh           what the library, its tests, benchmarks and the tool need
#   install-deps.sh --peers   also PCL (libpcl-dev, ~380 packages), for the optional PCL peers
#                             of `pbrlod sweep` (PBR_LOD_PEERS; scripts/test.sh asks for them)
set -euo pipefail
packages=(
  build-essential cmake ninja-build ccache pkg-config git
  # examples/strict_json.py holds every `pbrlod --json` output of the tests to strict JSON.
  python3
  # tools/copc-check: our COPC files read by the copc npm package (a reader we did not write).
  nodejs
  libeigen3-dev libcgal-dev libflann-dev libnanoflann-dev liblz4-dev libopenmesh-dev liblzf-dev
  # .spz Gaussian files: gzip (versions 1–3) and zstd (version 4) streams.
  zlib1g-dev libzstd-dev
  libgtest-dev libgmock-dev libbenchmark-dev libtbb-dev libcli11-dev libpng-dev
  # pbrlod build --distributed (the tool only; the library never links MPI).
  libopenmpi-dev openmpi-bin
  # examples/gl_viewer (optional; built when present): GLFW windows, EGL for the headless
  # renderer, Mesa's llvmpipe driver when the machine has no GPU; a virtual X server to test
  # its window.
  libglfw3-dev libegl-dev libgl-dev libegl-mesa0 libgl1-mesa-dri xvfb xauth x11-utils
  # The fuzz targets (scripts/fuzz.sh): clang 16 and its libFuzzer runtime. Not clang-14, the
  # default clang: it rejects libstdc++ 12's ranges (iota_view), which the Hierarchy concept uses.
  clang-16 libclang-rt-16-dev
)
[ "${1:-}" = "--peers" ] && packages+=(libpcl-dev)
missing=()
for p in "${packages[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
# Debian's nodejs comes without npm (Debian's npm package); NodeSource's includes it.
command -v npm > /dev/null || missing+=(npm)
SUDO=""
[ "$(id -u)" -eq 0 ] || SUDO="sudo"
if [ ${#missing[@]} -eq 0 ]; then
  echo "install-deps: all ${#packages[@]} packages present"
else
  echo "install-deps: installing ${missing[*]}"
  $SUDO apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}"
fi

# npm packages, pinned by their lock files: installed when missing or older than the lock.
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
for dir in "$root/tools/copc-check"; do
  if [ ! -d "$dir/node_modules" ] || [ "$dir/package-lock.json" -nt "$dir/node_modules" ]; then
    echo "install-deps: npm ci in ${dir#"$root"/}"
    (cd "$dir" && npm ci --no-audit --no-fund --loglevel=error && touch node_modules)
  fi
done
