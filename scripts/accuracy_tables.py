#!/usr/bin/env python3
"""Tables of docs/accuracy.md from a `pbrlod sweep` result: python3 accuracy_tables.py DIR/sweep.csv

Per (builder or peer, input), leading with what the user sees: the finest cut's PSNR inside the
input render's silhouette, silhouette IoU and cut → input distance (over the box diagonal);
then bytes per input point, PSNR inside the input's silhouette / against the builder's own finest
cut (means over the views; an identical frame, psnr empty or inf, counts as 60 dB) at three
tolerances, primitives and median frame time at tolerance 4, build time and peak build
memory, and the Hausdorff distance of the finest cut (fwd / bwd, over the box diagonal).
Peers have levels, not tolerances: their coarsest, middle and finest level stand in the three
columns."""
import csv
import statistics
import sys
from collections import defaultdict


def num(x, cap=60.0):
    try:
        v = float(x)
    except ValueError:
        return cap
    return cap if v != v or v == float("inf") else v


def main(path):
    rows = list(csv.DictReader(open(path)))
    by = defaultdict(list)
    for r in rows:
        by[(r["input"], r["builder"])].append(r)
    inputs = []
    for r in rows:
        if r["input"] not in inputs:
            inputs.append(r["input"])
    for inp in inputs:
        print(f"\n#### {inp}\n")
        print("| builder | finest: inner dB | IoU (min) | cut → input | bytes / input pt | "
              "coarse | tol 4 (peers: middle) | finest | "
              "primitives at 4 | frame ms at 4 (median) | build s | peak build MiB | "
              "input → cut at finest |")
        print("| --- | ---: | ---: | ---: | ---: | --- | --- | --- | ---: | ---: | ---: | ---: "
              "| ---: |")
        for (i, b), rs in by.items():
            if i != inp:
                continue
            # Coarse to fine by the primitives drawn (a peer's level counts cells across or a
            # cluster size: either direction).
            def prims(t):
                return statistics.mean(float(r["primitives"]) for r in rs
                                       if float(r["tolerance"]) == t)
            tols = sorted({float(r["tolerance"]) for r in rs}, key=prims)
            pick = [16.0, 4.0, 1.0] if 16.0 in tols and 1.0 in tols else \
                [tols[0], tols[len(tols) // 2], tols[-1]]
            cells = []
            for t in pick:
                sel = [r for r in rs if float(r["tolerance"]) == t]
                cells.append("%.1f / %.1f" % (statistics.mean(num(r["psnr_interior"]) for r in sel),
                                              statistics.mean(num(r["psnr"]) for r in sel)))
            mid = [r for r in rs if float(r["tolerance"]) == pick[1]]
            fin = [r for r in rs if float(r["tolerance"]) == pick[2]]
            prim = statistics.mean(float(r["primitives"]) for r in mid)
            fms = 1000 * statistics.median(float(r["frame_seconds"]) for r in mid)
            hf = statistics.mean(num(r["hausdorff_fwd"], 0) for r in fin)
            hb = statistics.mean(num(r["hausdorff_bwd"], 0) for r in fin)
            inner = statistics.mean(num(r["psnr_interior"]) for r in fin)
            iou = min(num(r["silhouette_iou"], 0) for r in fin)
            r0 = fin[0]
            peak = num(r0["peak_build_mib"], 0)
            print(f"| {b} | {inner:.1f} | {iou:.3f} | {hf:.4f} | "
                  f"{num(r0['bytes_per_input_point'], 0):.1f} | {cells[0]} | {cells[1]} | "
                  f"{cells[2]} | {prim:,.0f} | {fms:.1f} | {num(r0['build_seconds'], 0):.2f} | "
                  f"{f'{peak:.0f}' if peak > 0 else '–'} | {hb:.4f} |")


if __name__ == "__main__":
    main(sys.argv[1])
