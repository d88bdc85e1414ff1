#!/usr/bin/env bash
# A COPC file pbr_lod wrote, drawn by three.js in Debian's headless Chromium, against
# `pbrlod render` of the same view (issue 44): exports HIERARCHY to COPC, decodes its COPC levels
# 0..L with the copc npm package (tools/copc-browser/decode.mjs), draws them in a page served on
# 127.0.0.1 with the camera of `pbrlod render` (index.html, main.js, shoot.mjs), renders the same
# view with pbrlod — the INPUT at full detail when L is the finest COPC level, else the hierarchy
# at the coarsest tolerance whose cut draws at least 7/8 of the points decoded — and compares the
# two with `pbrlod compare`. Prints one JSON line; exits 1 when the silhouette IoU is below the
# floor.
#
#   copc_browser_check.sh HIERARCHY.lod INPUT [--level L] [--view AZ,EL,DIST] [--size WxH]
#                         [--up y|z] [--node-points N] [--min-iou X] [-o DIR]
#
#   INPUT        the file the hierarchy was built from (its bounding sphere frames the view, as
#                `pbrlod render` frames both; its full-detail render is the finest level's
#                reference)
#   --level L    COPC level to draw up to (default: the finest); negative counts from the
#                finest (-1: one above it)
#   --view, --size, --up   as `pbrlod render` (defaults 30,20,3, 512x512, y; z for LiDAR)
#   --node-points N   passed to `pbrlod export` (mean points per COPC node; smaller gives more
#                COPC levels)
#   --min-iou X  the floor (default 0.95 at the finest level, 0.75 at a coarser one, where the
#                reference is another point set with other splat sizes; the measurements that
#                choose them are in tools/copc-browser/README.md)
#   -o DIR       where the files go (default: a new folder under /tmp)
#
# Installs Debian's chromium (and nodejs/npm) when missing, and runs `npm ci` in
# tools/copc-browser when its node_modules is missing or older than the lock file. The pbrlod
# tool must be built (PBRLOD overrides its path).
set -Eeuo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
tool="$root/tools/copc-browser"
pbrlod="${PBRLOD:-$root/${BUILD_DIR:-build}/release/examples/pbrlod}"

usage() {
  sed -n '11,12p' "$0" | sed 's/^# *//' >&2
  exit 2
}
[ $# -ge 2 ] || usage
hierarchy="$1" input="$2"
shift 2
level="" view="30,20,3" size="512x512" up="y" node_points="" min_iou="" out=""
while [ $# -gt 0 ]; do
  case "$1" in
    --level) level="$2"; shift 2 ;;
    --view) view="$2"; shift 2 ;;
    --size) size="$2"; shift 2 ;;
    --up) up="$2"; shift 2 ;;
    --node-points) node_points="$2"; shift 2 ;;
    --min-iou) min_iou="$2"; shift 2 ;;
    -o) out="$2"; shift 2 ;;
    *) echo "copc_browser_check: unknown argument $1" >&2; usage ;;
  esac
done
[ -f "$hierarchy" ] || [ -d "$hierarchy" ] || { echo "copc_browser_check: no $hierarchy" >&2; exit 1; }
[ -e "$input" ] || { echo "copc_browser_check: no $input" >&2; exit 1; }
[ -x "$pbrlod" ] || { echo "copc_browser_check: $pbrlod is not built (scripts/demo.sh builds it)" >&2; exit 1; }
[ -n "$out" ] || out="$(mktemp -d /tmp/copc-browser.XXXXXX)"
mkdir -p "$out"
log="$out/log.txt"
: > "$log"
start=$(date +%s.%N)
exec 3>&2  # the trap's stderr: the failing step's own stderr goes to the log
trap 'echo "copc_browser_check: a step failed; its messages are in $log" >&3' ERR

# --- what it needs ---
SUDO=""
[ "$(id -u)" -eq 0 ] || SUDO="sudo"
missing=()
command -v chromium > /dev/null || missing+=(chromium)
command -v node > /dev/null || missing+=(nodejs)
command -v npm > /dev/null || missing+=(npm)
if [ ${#missing[@]} -gt 0 ]; then
  echo "copc_browser_check: installing ${missing[*]}" >&2
  $SUDO apt-get update -qq >> "$log" 2>&1
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq "${missing[@]}" >> "$log" 2>&1
fi
if [ ! -d "$tool/node_modules" ] || [ "$tool/package-lock.json" -nt "$tool/node_modules" ]; then
  echo "copc_browser_check: npm ci in tools/copc-browser" >&2
  (cd "$tool" && npm ci --no-audit --no-fund --loglevel=error && touch node_modules) >> "$log" 2>&1
fi
chromium_exe="$(command -v chromium)"

# One field of a JSON object (a file), or of the expression given, through node.
jget() { node -e 'const j=JSON.parse(require("fs").readFileSync(process.argv[1],"utf8"));
  const v=(0,eval)("(j)=>"+process.argv[2])(j); console.log(typeof v==="object"?JSON.stringify(v):v)' "$1" "$2"; }
run() { echo "+ $*" >> "$log"; "$@"; }

# --- export, frame, decode ---
copc="$out/hierarchy.copc.laz"
export_args=()
[ -n "$node_points" ] && export_args+=(--node-points "$node_points")
run nice "$pbrlod" export "$hierarchy" -o "$copc" "${export_args[@]}" --json > "$out/export.json" 2>> "$log"
copc_levels=$(jget "$out/export.json" 'j.copc_levels')
if [ -z "$level" ]; then level=$((copc_levels - 1)); fi
if [ "$level" -lt 0 ]; then level=$((copc_levels - 1 + level)); fi
if [ "$level" -lt 0 ] || [ "$level" -ge "$copc_levels" ]; then
  echo "copc_browser_check: --level: the file has COPC levels 0..$((copc_levels - 1))" >&2
  exit 2
fi
# The view is framed by the input's bounding sphere about its box centre, as `pbrlod render`
# frames a hierarchy (the bounds it recorded of its input) and the input itself.
run nice "$pbrlod" stats "$input" --json > "$out/input_stats.json" 2>> "$log"
centre=$(jget "$out/input_stats.json" '[j.bounding_sphere.x,j.bounding_sphere.y,j.bounding_sphere.z].map(v=>v.toPrecision(17)).join(",")')
radius=$(jget "$out/input_stats.json" 'j.bounding_sphere.radius.toPrecision(17)')
run nice node "$tool/decode.mjs" "$copc" --level "$level" -o "$out/decoded" > "$out/decode.json" 2>> "$log"
points=$(jget "$out/decode.json" 'j.points')

finest=0
[ "$level" -eq $((copc_levels - 1)) ] && finest=1
if [ -z "$min_iou" ]; then
  if [ "$finest" = 1 ]; then min_iou=0.95; else min_iou=0.75; fi
fi
# Shaded as the reference is: the input's render shades only an input with normals (or faces),
# the hierarchy's render shades (the point-octree estimates normals; the COPC file has them).
shade=1
if [ "$finest" = 1 ]; then
  shade=$(jget "$out/input_stats.json" 'j.kind==="mesh"||/normal/.test(j.attributes)?1:0')
fi

# --- the browser ---
run nice node "$tool/shoot.mjs" --data "$out/decoded" --centre="$centre" --radius "$radius" \
  --view="$view" --size "$size" --up "$up" --shade "$shade" --chromium "$chromium_exe" \
  -o "$out/threejs.png" > "$out/shoot.json" 2>> "$log"

# --- pbrlod's render of the same view ---
view_args=(--view="$view" --size "$size" --up "$up")
run nice "$pbrlod" render "$input" "${view_args[@]}" -o "$out/pbrlod_input.png" --json \
  > "$out/render_input.json" 2>> "$log"
if [ "$finest" = 1 ]; then
  reference="$out/pbrlod_input.png"
  reference_kind="input at full detail"
  reference_tolerance=null
  reference_points=$(jget "$out/render_input.json" 'j.primitives')
else
  # The coarsest cut of the hierarchy (the largest tolerance) that draws at least 7/8 of the
  # decoded points: COPC levels 0..L hold our cut at level L + shift plus the coarser
  # representatives above it, about 1/7 more for an octree (docs/io.md "COPC out").
  target=$(( (points * 7 + 7) / 8 ))
  best=""
  for t in 0.25 0.5 1 2 3 4 6 8 12 16 24 32 48 64 96 128 256 512 1024; do
    run nice "$pbrlod" render "$hierarchy" "${view_args[@]}" --tolerance "$t" \
      -o "$out/pbrlod_t$t.png" --json > "$out/render_t$t.json" 2>> "$log"
    drawn=$(jget "$out/render_t$t.json" 'j.points+j.splats+j.triangles')
    if [ "$drawn" -lt "$target" ]; then
      [ -n "$best" ] || best="$t"  # even the finest cut draws fewer
      break
    fi
    best="$t"
  done
  reference="$out/pbrlod_hierarchy.png"
  cp "$out/pbrlod_t$best.png" "$reference"
  cp "$out/render_t$best.json" "$out/render_hierarchy.json"
  reference_kind="hierarchy at --tolerance $best"
  reference_tolerance="$best"
  reference_points=$(jget "$out/render_hierarchy.json" 'j.points+j.splats+j.triangles')
fi
run nice "$pbrlod" compare "$reference" "$out/threejs.png" --json > "$out/compare.json" 2>> "$log"
run nice "$pbrlod" compare "$out/pbrlod_input.png" "$out/threejs.png" --json > "$out/compare_input.json" 2>> "$log"
run nice node "$tool/montage.mjs" "$reference" "$out/threejs.png" --chromium "$chromium_exe" \
  --labels "pbrlod render: $reference_kind" "three.js in Chromium: COPC levels 0..$level" \
  -o "$out/side_by_side.png" > "$out/montage.json" 2>> "$log"

trap - ERR
seconds=$(node -e 'console.log(((Date.now()/1000)-(+process.argv[1])).toFixed(1))' "$start")
node -e '
const fs = require("fs");
const [out, hierarchy, input, level, view, size, up, kind, tol, refPoints, minIou, seconds] = process.argv.slice(1);
const r = (f) => JSON.parse(fs.readFileSync(`${out}/${f}`, "utf8"));
const ex = r("export.json"), dec = r("decode.json"), shot = r("shoot.json");
const cmp = r("compare.json"), cin = r("compare_input.json"), mon = r("montage.json");
const iou = cmp.silhouette_iou;
const j = {
  hierarchy, input, copc: `${out}/hierarchy.copc.laz`, copc_levels: ex.copc_levels,
  level_shift: ex.level_shift, copc_level: +level,
  hierarchy_levels_drawn: Object.keys(dec.points_per_hierarchy_level).map(Number),
  view, size, up, points_drawn: dec.points, reference: kind,
  reference_tolerance: tol === "null" ? null : +tol, reference_primitives: +refPoints,
  silhouette_iou: iou, psnr: cmp.psnr, psnr_interior: cmp.psnr_interior,
  silhouette_iou_vs_input: cin.silhouette_iou, psnr_vs_input: cin.psnr,
  // framing: each silhouette bounding box [x0, y0, x1, y1] and the centroid offset (pixels)
  box_reference: mon.first.box, box_threejs: mon.second.box, centroid_offset_px: mon.centroid_offset_px.map((v) => +v.toFixed(2)),
  splats: shot.splats,
  min_iou: +minIou, pass: iou >= +minIou,
  browser: shot.browser, webgl: shot.webgl, three: shot.three,
  images: { threejs: `${out}/threejs.png`, pbrlod: `${out}/${kind.startsWith("input") ? "pbrlod_input" : "pbrlod_hierarchy"}.png`,
            side_by_side: `${out}/side_by_side.png` },
  seconds: +seconds,
};
console.log(JSON.stringify(j));
process.exit(j.pass ? 0 : 1);
' "$out" "$hierarchy" "$input" "$level" "$view" "$size" "$up" "$reference_kind" \
  "$reference_tolerance" "$reference_points" "$min_iou" "$seconds"
