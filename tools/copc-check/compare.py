#!/usr/bin/env python3
"""Exports a hierarchy as COPC with `pbrlod export`, reads the file back with the `copc` npm
package (check.mjs: a reader pbr_lod did not write) and compares what it finds with
`pbrlod stats` of the same file and with the export's own report. Exit 0 when they agree, 1 with
the differences listed, 77 (CTest's skip) when the npm packages are not installed and CI is not
set (`npm ci --prefix tools/copc-check` installs them; scripts/install-deps.sh does).

    compare.py PBRLOD HIERARCHY OUT.copc.laz [EXPORT ARGS...]
"""
import json
import math
import os
import shutil
import subprocess
import sys

here = os.path.dirname(os.path.abspath(__file__))


def run_json(cmd):
    out = subprocess.run(cmd, check=True, capture_output=True, text=True).stdout
    return json.loads(out.strip().splitlines()[-1])


def main():
    pbrlod, hierarchy, out = sys.argv[1:4]
    extra = sys.argv[4:]
    node = shutil.which("node")
    if node is None or not os.path.isdir(os.path.join(here, "node_modules", "copc")):
        msg = "copc-check: node or the copc npm package is missing (npm ci --prefix tools/copc-check)"
        if os.environ.get("CI") == "true":
            print(msg + "; CI runs this check", file=sys.stderr)
            return 1
        print(msg + ": skipped")
        return 77
    exported = run_json([pbrlod, "export", hierarchy, "--format", "copc", "-o", out, "--json",
                         *extra])
    stats = run_json([pbrlod, "stats", out, "--json"])
    seen = run_json([node, os.path.join(here, "check.mjs"), out])
    problems = []

    def same(what, a, b):
        if a != b:
            problems.append(f"{what}: {a!r} != {b!r}")

    n = exported["points"]
    same("points: copc.js header vs export", seen["header_points"], n)
    same("points: copc.js decoded vs export", seen["points"], n)
    same("points: pbrlod stats vs export", stats["points"], n)
    same("nodes with points", seen["nodes"], exported["copc_nodes"])
    same("empty nodes", seen["empty_nodes"], exported["copc_empty_nodes"])
    same("COPC levels", seen["levels"], exported["copc_levels"])
    same("points outside their voxel", seen["points_outside_their_voxel"], 0)
    same("normals neither unit nor zero", seen["normals_not_unit"], 0)
    attrs = exported["attributes"].split("+")
    same("normal extra bytes", seen["extra_bytes"],
         ["NormalX", "NormalY", "NormalZ"] if "normal" in attrs else [])
    same("point format", seen["point_format"], 7 if "colour" in attrs else 6)
    same("spatial reference", seen["wkt"], exported["spatial_reference"])
    levels = {int(k): v for k, v in seen["points_per_hierarchy_level"].items()}
    same("points over hierarchy levels", sum(levels.values()), n)
    same("hierarchy levels", max(levels) + 1 if levels else 0, exported["hierarchy_levels"])
    # With the default --coarse-points samples every coarse point is one of the leaves' samples:
    # the file holds no position the leaves do not.
    if exported["coarse_points"] == "samples" and seen["distinct_positions"] > exported["leaf_samples"]:
        problems.append(f"{seen['distinct_positions']} distinct positions, more than the "
                        f"{exported['leaf_samples']} leaf samples")
    # The bounding sphere pbrlod stats gives (about the box centre, in float) and copc.js's.
    a, b = stats["bounding_sphere"], seen["bounding_sphere"]
    r = max(b["radius"], 1e-300)
    gap = math.dist([a["x"], a["y"], a["z"]], [b["x"], b["y"], b["z"]])
    if gap > 1e-5 * r + 2 * max(seen["scale"]):
        problems.append(f"bounding sphere centres {gap} apart (radius {r})")
    if abs(a["radius"] - b["radius"]) > 1e-5 * r + 2 * max(seen["scale"]):
        problems.append(f"bounding sphere radii {a['radius']} != {b['radius']}")
    for p in problems:
        print("copc-check: " + p, file=sys.stderr)
    print(json.dumps({"export": exported, "copc_js": seen, "agree": not problems}))
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main())
