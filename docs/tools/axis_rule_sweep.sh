#!/usr/bin/env bash
# The point-octree's ellipse axis rule, a' = sqrt(lambda) (default) against the paper's a' = lambda,
# each with and without the bounding-circle guard (circle_guard): splats drawn and PSNR against the
# same hierarchy's tolerance-0 cut, per input, view and tau.
# Prints CSV. docs/point-octree.md ("Axis rule") quotes its output.
#   bash docs/tools/axis_rule_sweep.sh [PBRLOD] [DATA]
set -euo pipefail
P="${1:-build/release/examples/pbrlod}"
D="${2:-../shared/data}"
tmp="$(mktemp -d)"
trap 'rm -rf "$tmp"' EXIT
echo "input,axes,circle_guard,circle_fallbacks,nodes,view,tau,splats,psnr_db,hole_fraction"
for in in bun_zipper happy_vrip_res3; do
  for config in sqrt:1 eigenvalue:1 sqrt:0 eigenvalue:0; do
    a="${config%:*}" g="${config#*:}"
    lod="$tmp/${in}_$a$g.lod"
    "$P" build --method point-octree --param axes=$a --param circle_guard=$g "$D/$in.ply" \
      -o "$lod" > /dev/null
    s=$("$P" stats --json "$lod" | python3 -c \
      'import json,sys; j=json.load(sys.stdin); print(j["circle_fallbacks"], j["nodes"], sep=",")')
    for v in 30,20,3 120,10,1.5 250,30,8; do
      "$P" render "$lod" --tolerance 0 --view $v --size 1024x1024 -o "$tmp/ref.png" > /dev/null
      for t in 1 2 4 8 16; do
        j=$("$P" render "$lod" --tolerance $t --view $v --size 1024x1024 -o "$tmp/img.png" --json)
        c=$("$P" compare "$tmp/ref.png" "$tmp/img.png" --json)
        python3 - "$in,$a,$g,$s,\"$v\",$t" "$j" "$c" << 'PY'
import json, sys
head, j, c = sys.argv[1], json.loads(sys.argv[2]), json.loads(sys.argv[3])
psnr = c.get("psnr")
print(f'{head},{j["splats"]},{"inf" if psnr is None else f"{psnr:.1f}"},{c["hole_fraction"]:.1e}')
PY
      done
    done
  done
done
