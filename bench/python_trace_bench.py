#!/usr/bin/env python3
"""Overhead of the Python module: kestrel.trace from Python against the C++ batch API on the
same rays, the same scene and the same build, alternating in one run.

The C++ figure is what `kestrel trace --repeat R` prints as its median trace time (the batch
API, kestrel::trace, timed around the call); the Python figure is the median wall time of
kestrel.trace(accel, rays) (argument checks, output allocation, GIL release, the trace).

    PYTHONPATH=build/release/python python3 bench/python_trace_bench.py [--scene S] [--rays N]
        [--kind diffuse|primary|shadow] [--threads T] [--rounds K] [--json out.json]
"""
import argparse
import json
import os
import re
import statistics
import subprocess
import sys
import tempfile
import time

import numpy as np

import kestrel


def main():
    here = os.path.dirname(os.path.abspath(__file__))
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--scene", default="builtin:cornell_box")
    p.add_argument("--view", default="framing")
    p.add_argument("--kind", default="diffuse", choices=["primary", "shadow", "diffuse"])
    p.add_argument("--rays", type=int, default=1_000_000, help="rays (at least; whole images of primary rays)")
    p.add_argument("--threads", type=int, default=1)
    p.add_argument("--rounds", type=int, default=3, help="alternations of C++ and Python")
    p.add_argument("--repeat", type=int, default=5, help="timed traces per round (median)")
    p.add_argument("--cli", default=os.path.join(here, "..", "build", "release", "apps", "kestrel", "kestrel"))
    p.add_argument("--json")
    a = p.parse_args()

    with tempfile.TemporaryDirectory() as tmp:
        rays_path = os.path.join(tmp, "b.rays")
        side = int(np.ceil(np.sqrt(a.rays)))
        subprocess.run([a.cli, "rays", a.scene, "--view", a.view, "--kind", a.kind, "--res", f"{side}x{side}",
                        "-o", rays_path], check=True, capture_output=True)
        rays = kestrel.read_rays(rays_path)
        scene = kestrel.load_scene(a.scene)
        accel = kestrel.build_accel(scene, threads=a.threads)
        any_hit = a.kind == "shadow"
        cpp, py, py_out = [], [], []
        reused = np.empty(len(rays), dtype=kestrel.hit_dtype)
        for _ in range(a.rounds):
            out = subprocess.run([a.cli, "trace", a.scene, "--rays", rays_path, "--hits", os.path.join(tmp, "b.hits"),
                                  "--threads", str(a.threads), "--repeat", str(a.repeat)]
                                 + (["--any-hit"] if any_hit else []), check=True, capture_output=True, text=True).stdout
            cpp.append(float(re.search(r"trace\s+([0-9.]+) ms", out).group(1)))
            times = []
            for _ in range(a.repeat):
                t0 = time.perf_counter()
                kestrel.trace(accel, rays, any_hit=any_hit, threads=a.threads)
                times.append((time.perf_counter() - t0) * 1e3)
            py.append(statistics.median(times))
            times = []
            for _ in range(a.repeat):
                t0 = time.perf_counter()
                kestrel.trace(accel, rays, any_hit=any_hit, threads=a.threads, out=reused)
                times.append((time.perf_counter() - t0) * 1e3)
            py_out.append(statistics.median(times))
        expected = kestrel.read_hits(os.path.join(tmp, "b.hits"))
        got = kestrel.trace(accel, rays, any_hit=any_hit, threads=a.threads)
        same = bool(np.array_equal(got["prim_id"], expected["prim_id"]) and
                    np.array_equal(got["t"].view(np.uint32), expected["t"].view(np.uint32)))
    c, q, r = statistics.median(cpp), statistics.median(py), statistics.median(py_out)
    result = {"scene": a.scene, "kind": a.kind, "rays": len(rays), "threads": a.threads, "rounds": a.rounds,
              "cpp_ms": c, "python_ms": q, "python_out_ms": r, "python_over_cpp": q / c,
              "python_out_over_cpp": r / c, "overhead_percent": 100 * (q / c - 1),
              "hits_identical": same}
    print(f"scene {a.scene}, {len(rays)} {a.kind} rays, {a.threads} thread(s), median of {a.rounds} rounds x {a.repeat}")
    print(f"  C++ batch API (kestrel trace)  {c:9.2f} ms   {len(rays) / c / 1e3:7.2f} Mrays/s")
    print(f"  Python kestrel.trace           {q:9.2f} ms   {len(rays) / q / 1e3:7.2f} Mrays/s")
    print(f"  Python kestrel.trace(out=...)  {r:9.2f} ms   {len(rays) / r / 1e3:7.2f} Mrays/s")
    print(f"  Python / C++                   {q / c:9.3f}   ({100 * (q / c - 1):+.1f} %); with out= {r / c:.3f} "
          f"({100 * (r / c - 1):+.1f} %); hits identical: {same}")
    if a.json:
        with open(a.json, "w") as f:
            json.dump(result, f, indent=2)
    return 0 if same else 1


if __name__ == "__main__":
    sys.exit(main())
