#!/usr/bin/env python3
"""Turns bench_pop's JSON (--benchmark_out) into docs/images/pop_sweep.svg: points and triangles
drawn, PSNR and frame time against the splat-size threshold (the paper's Figure 6), for one mesh
and the paper's mode (simplified splatting, eye-space-z splat size). Standard library only.
Usage: pop_sweep_plot.py bench.json out.svg [mesh_index]"""
import json
import math
import sys

src, dst = sys.argv[1], sys.argv[2]
mesh = sys.argv[3] if len(sys.argv) > 3 else "1"
rows = {}
for b in json.load(open(src))["benchmarks"]:
    name = b["name"]
    if not name.startswith(f"bm_threshold/mesh:{mesh}/") or b.get("aggregate_name", "median") != "median":
        continue
    if "/mode:0" not in name:
        continue
    tol = int(name.split("tol_x10:")[1].split("/")[0]) / 10
    rows[tol] = (b["points"], b["triangles"], b["psnr_db"], b["real_time"])
label = {"0": "bunny", "1": "Buddha (res3)"}.get(mesh, mesh)
ts = sorted(rows)
W, H, L, R, T, B = 640, 360, 60, 170, 30, 50
pw, ph = W - L - R, H - T - B
def x(t):
    return L + pw * (math.log(t) - math.log(ts[0])) / (math.log(ts[-1]) - math.log(ts[0]))
series = [
    ("points drawn", [rows[t][0] for t in ts], "#d62728"),
    ("triangles drawn", [rows[t][1] for t in ts], "#1f77b4"),
    ("PSNR (dB)", [rows[t][2] for t in ts], "#9467bd"),
    ("frame ms", [rows[t][3] for t in ts], "#2ca02c"),
]
out = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{W}" height="{H}" font-family="sans-serif" font-size="12">',
       f'<rect width="{W}" height="{H}" fill="white"/>',
       f'<text x="{L}" y="18">POP threshold sweep ({label}, 1024², eye-space-z splat size)</text>',
       f'<line x1="{L}" y1="{T+ph}" x2="{L+pw}" y2="{T+ph}" stroke="black"/>']
for t in ts:
    out.append(f'<line x1="{x(t):.1f}" y1="{T+ph}" x2="{x(t):.1f}" y2="{T+ph+5}" stroke="black"/>')
    out.append(f'<text x="{x(t):.1f}" y="{T+ph+18}" text-anchor="middle">{t:g}</text>')
out.append(f'<text x="{L+pw/2}" y="{H-8}" text-anchor="middle">threshold (pixels, log scale)</text>')
for i, (name, ys, colour) in enumerate(series):
    top = max(ys) * 1.1 or 1
    pts = " ".join(f"{x(t):.1f},{T + ph - ph * y / top:.1f}" for t, y in zip(ts, ys))
    out.append(f'<polyline points="{pts}" fill="none" stroke="{colour}" stroke-width="2"/>')
    for t, y in zip(ts, ys):
        out.append(f'<circle cx="{x(t):.1f}" cy="{T + ph - ph * y / top:.1f}" r="3" fill="{colour}"/>')
        out.append(f'<text x="{x(t)+4:.1f}" y="{T + ph - ph * y / top - 4:.1f}" fill="{colour}" font-size="10">{y:.3g}</text>')
    out.append(f'<rect x="{L+pw+15}" y="{T+20*i}" width="12" height="12" fill="{colour}"/>')
    out.append(f'<text x="{L+pw+32}" y="{T+20*i+10}">{name}</text>')
out.append(f'<text x="{L+pw+15}" y="{T+100}" font-size="10">each series scaled to its max</text>')
out.append("</svg>")
open(dst, "w").write("\n".join(out))
