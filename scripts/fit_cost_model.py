#!/usr/bin/python3
"""Fits the cost model behind BuildQuality::automatic to the amortization CSV written by
`kestrel_trace_bench --amortization F.csv`, and prints the C++ table for src/bvh/cost_model.cpp.

Model, per builder b, for n primitives and R rays per build (single thread):
    seconds(b, n, R) = n * build_ns[b] * 1e-9 + R * (a + c * log2 n) * ray_factor[b] * 1e-9
build_ns[b]   median over scenes of build_ms / n (full build_accel, incl. the wide collapse)
a, c          least-squares fit of binned's ns per ray against log2 n over the scenes
ray_factor[b] median over scenes of (binned Mrays/s) / (b's Mrays/s): trace cost relative to binned
"""
import csv, math, statistics, sys
from collections import defaultdict

rows = list(csv.DictReader(open(sys.argv[1])))
points = {}
for r in rows:
    points[(r["scene"], r["method"])] = (int(r["prims"]), float(r["build_ms"]), float(r["mrays_per_s"]))
# Scenes under 1000 triangles measure fixed overheads, not per-primitive costs.
scenes = sorted({s for s, _ in points if points[(s, "binned")][0] >= 1000})
builders = ["median", "lbvh", "binned", "sweep", "spatial"]
build_ns, ray_factor = {}, {}
for b in builders:
    build_ns[b] = statistics.median(points[(s, b)][1] * 1e6 / points[(s, b)][0] for s in scenes if (s, b) in points)
    ray_factor[b] = statistics.median(points[(s, "binned")][2] / points[(s, b)][2] for s in scenes if (s, b) in points)
xs = [math.log2(points[(s, "binned")][0]) for s in scenes]
ys = [1e3 / points[(s, "binned")][2] for s in scenes]  # ns per ray
mx, my = statistics.mean(xs), statistics.mean(ys)
c = sum((x - mx) * (y - my) for x, y in zip(xs, ys)) / max(1e-9, sum((x - mx) ** 2 for x in xs))
a = my - c * mx
print(f"// fitted from {sys.argv[1].split('/')[-1]}: scenes {', '.join(scenes)}")
print(f"constexpr double ray_ns_base = {a:.2f}, ray_ns_per_log2n = {c:.2f};")
for b in builders:
    print(f"  {{Builder::{b}, {build_ns[b]:.1f}, {ray_factor[b]:.3f}}},")
