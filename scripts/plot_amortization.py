#!/usr/bin/python3
"""Draws the amortization curve from `kestrel_trace_bench --amortization F.csv`:
effective Mrays/s = R / (T_build + R / throughput) against R, the rays traced per build,
one panel per scene, one line per builder (kestrel) and per Embree quality, plus what
quality=auto picks. Prints the crossover points (where the best method changes) as markdown.

    python3 scripts/plot_amortization.py amortization.csv docs/amortization.png
"""
import csv, sys
from collections import defaultdict

import matplotlib
matplotlib.use("Agg")
import matplotlib.pyplot as plt

src, out = sys.argv[1], sys.argv[2]
curves = defaultdict(lambda: defaultdict(list))  # scene -> method -> [(R, eff)]
prims = {}
for r in csv.DictReader(open(src)):
    curves[r["scene"]][r["method"]].append((float(r["rays_per_build"]), float(r["effective_mrays_per_s"])))
    prims[r["scene"]] = int(r["prims"])

scenes = list(curves)
cols = min(3, len(scenes))
rows = (len(scenes) + cols - 1) // cols
fig, axes = plt.subplots(rows, cols, figsize=(5.2 * cols, 4.0 * rows), squeeze=False)
style = {"median": ":", "lbvh": "-", "binned": "-", "sweep": "-", "spatial": "-", "treelet": "-.", "auto": "--"}
print("| scene | triangles | best of all (crossovers) | best kestrel builder (crossovers) |")
print("|---|---:|---|---|")
for i, scene in enumerate(scenes):
    ax = axes[i // cols][i % cols]
    for method, pts in curves[scene].items():
        pts.sort()
        xs, ys = zip(*pts)
        ls = style.get(method, "-")
        lw = 2.5 if method == "auto" else 1.4
        color = "black" if method == "auto" else None
        if method.startswith("embree"):
            ls = "--"
        ax.plot(xs, ys, ls, label=method, linewidth=lw, color=color)
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_title(f"{scene} ({prims[scene]:,} triangles)")
    ax.set_xlabel("rays traced per build R")
    ax.set_ylabel("effective Mrays/s, one thread")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7)
    # Crossovers among all fixed methods (auto excluded).
    def crossovers(methods):
        rs = sorted(next(iter(methods.values())).keys())
        segments, last = [], None
        for R in rs:
            best = max(methods, key=lambda m: methods[m][R])
            if best != last:
                segments.append((R, best))
                last = best
        return "; ".join(f"{m} from R = {R:.2g}" for R, m in segments)
    fixed = {m: dict(p) for m, p in curves[scene].items() if m != "auto"}
    ours = {m: p for m, p in fixed.items() if not m.startswith("embree")}
    print(f"| {scene} | {prims[scene]:,} | {crossovers(fixed)} | {crossovers(ours)} |")
for j in range(len(scenes), rows * cols):
    axes[j // cols][j % cols].axis("off")
fig.suptitle("Amortization: effective throughput R / (T_build + R / throughput), single thread")
fig.tight_layout()
fig.savefig(out, dpi=110)
print(f"\nwrote {out}")
