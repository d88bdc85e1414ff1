#!/usr/bin/env python3
"""Turns bench_point_octree's JSON (--benchmark_out) into docs/images/point_octree_sweep.svg:
PSNR, splats drawn and frame time against the screen tolerance τ. Standard library only."""
import json
import sys

src, dst = sys.argv[1], sys.argv[2]
rows = {}
for b in json.load(open(src))["benchmarks"]:
    name = b["name"]
    if not name.startswith("bm_tolerance/") or b.get("aggregate_name", "median") != "median":
        continue
    tau = int(name.split("tau_px:")[1].split("_")[0].split("/")[0])
    rows[tau] = (b["psnr_db"], b["fraction_drawn"], b["real_time"])
taus = sorted(rows)
W, H, L, R, T, B = 640, 360, 60, 150, 30, 50
pw, ph = W - L - R, H - T - B
import math
def x(t):
    return L + pw * (math.log2(t) - math.log2(taus[0])) / (math.log2(taus[-1]) - math.log2(taus[0]))
series = [
    ("PSNR (dB)", [rows[t][0] for t in taus], "#1f77b4"),
    ("fraction drawn (%)", [100 * rows[t][1] for t in taus], "#d62728"),
    ("frame ms", [rows[t][2] for t in taus], "#2ca02c"),
]
out = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{W}" height="{H}" font-family="sans-serif" font-size="12">',
       f'<rect width="{W}" height="{H}" fill="white"/>',
       f'<text x="{L}" y="18">point-octree tolerance sweep (1M-point surface, 1024²)</text>',
       f'<line x1="{L}" y1="{T+ph}" x2="{L+pw}" y2="{T+ph}" stroke="black"/>']
for t in taus:
    out.append(f'<line x1="{x(t):.1f}" y1="{T+ph}" x2="{x(t):.1f}" y2="{T+ph+5}" stroke="black"/>')
    out.append(f'<text x="{x(t):.1f}" y="{T+ph+18}" text-anchor="middle">{t}</text>')
out.append(f'<text x="{L+pw/2}" y="{H-8}" text-anchor="middle">τ (pixels, log scale)</text>')
for i, (label, ys, colour) in enumerate(series):
    top = max(ys) * 1.1 or 1
    pts = " ".join(f"{x(t):.1f},{T + ph - ph * y / top:.1f}" for t, y in zip(taus, ys))
    out.append(f'<polyline points="{pts}" fill="none" stroke="{colour}" stroke-width="2"/>')
    for t, y in zip(taus, ys):
        out.append(f'<circle cx="{x(t):.1f}" cy="{T + ph - ph * y / top:.1f}" r="3" fill="{colour}"/>')
        out.append(f'<text x="{x(t)+4:.1f}" y="{T + ph - ph * y / top - 4:.1f}" fill="{colour}" font-size="10">{y:.3g}</text>')
    out.append(f'<rect x="{L+pw+15}" y="{T+20*i}" width="12" height="12" fill="{colour}"/>')
    out.append(f'<text x="{L+pw+32}" y="{T+20*i+10}">{label}</text>')
out.append(f'<text x="{L+pw+15}" y="{T+80}" font-size="10">each series scaled to its max</text>')
out.append("</svg>")
open(dst, "w").write("\n".join(out))
