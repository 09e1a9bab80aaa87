#!/usr/bin/env python3
"""Distributed rendering on this machine: one frame through `kestrel render` as 1 rank x 1
thread, 1 rank x 2 threads and N ranks x 1 thread (mpirun on loopback), alternating, medians.

Prints each configuration's frame time, the per-rank busy time that `kestrel render` reports
under mpirun, and three ratios:
- load balance = sum of rank busy time / (ranks x frame time): how well the dynamic tiles keep
  every rank busy (1.0 = no rank waits);
- ranks vs threads = time(1 rank x 2 threads) / time(2 ranks x 1 thread): what MPI costs
  against threads on the same cores;
- strong-scaling efficiency = time(1 x 1) / (ranks x time(ranks x 1)), printed for 2 threads
  too: what the machine's two vCPUs allow (they deliver between one and two cores here,
  depending on the day).

    python3 bench/distributed_bench.py [--scene S] [--view V] [--res WxH] [--spp N] [--ranks 2]
        [--rounds 3] [--json out.json]
"""
import argparse
import json
import os
import re
import statistics
import subprocess
import sys
import tempfile


def run(cmd):
    out = subprocess.run(cmd, check=True, capture_output=True, text=True).stdout
    ms = float(re.search(r"render\s+\d+ spp in ([0-9.]+) ms", out).group(1))
    busy = [float(b) for b in re.findall(r"busy ([0-9.]+) ms", out)]
    return ms, busy


def main():
    here = os.path.dirname(os.path.abspath(__file__))
    sponza = os.path.normpath(os.path.join(here, "..", "..", "shared", "scenes", "dabrovic_sponza", "sponza.obj"))
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--scene", default=sponza if os.path.exists(sponza) else "builtin:cornell_box")
    p.add_argument("--view", default="inside" if os.path.exists(sponza) else "front")
    p.add_argument("--res", default="320x180")
    p.add_argument("--spp", type=int, default=64)
    p.add_argument("--ranks", type=int, default=2)
    p.add_argument("--rounds", type=int, default=3)
    p.add_argument("--cli", default=os.path.join(here, "..", "build", "release", "apps", "kestrel", "kestrel"))
    p.add_argument("--json")
    a = p.parse_args()
    mpirun = ["mpirun", "--oversubscribe"] + (["--allow-run-as-root"] if os.geteuid() == 0 else [])
    with tempfile.TemporaryDirectory() as tmp:
        base = ["render", a.scene, "--view", a.view, "--res", a.res, "--spp", str(a.spp), "--seed", "1", "--quiet",
                "-o", os.path.join(tmp, "f.exr")]
        configs = {
            "1 rank x 1 thread": [a.cli] + base + ["--threads", "1"],
            "1 rank x 2 threads": [a.cli] + base + ["--threads", "2"],
            f"{a.ranks} ranks x 1 thread": mpirun + ["-n", str(a.ranks), a.cli] + base + ["--threads", "1"],
        }
        times = {k: [] for k in configs}
        balance = []
        for _ in range(a.rounds):
            for name, cmd in configs.items():
                ms, busy = run(cmd)
                times[name].append(ms)
                if busy:
                    balance.append(sum(busy) / (len(busy) * ms))
    med = {k: statistics.median(v) for k, v in times.items()}
    t11, t12, tn = med["1 rank x 1 thread"], med["1 rank x 2 threads"], med[f"{a.ranks} ranks x 1 thread"]
    result = {"scene": a.scene, "view": a.view, "res": a.res, "spp": a.spp, "ranks": a.ranks, "rounds": a.rounds,
              "ms": med, "load_balance": statistics.median(balance),
              "ranks_vs_threads": t12 / tn if a.ranks == 2 else None,
              "strong_scaling_ranks": t11 / (a.ranks * tn), "strong_scaling_threads": t11 / (2 * t12)}
    print(f"{a.scene} ({a.view}), {a.res}, {a.spp} spp; median of {a.rounds} alternating rounds")
    for k, v in med.items():
        print(f"  {k:22} {v:10.1f} ms")
    print(f"  load balance ({a.ranks} ranks, busy / (ranks x frame)): {result['load_balance']:.3f}")
    if a.ranks == 2:
        print(f"  1 rank x 2 threads / 2 ranks x 1 thread: {t12 / tn:.3f}")
    print(f"  strong scaling vs 1 x 1: {a.ranks} ranks {result['strong_scaling_ranks']:.3f}, "
          f"2 threads {result['strong_scaling_threads']:.3f}")
    if a.json:
        with open(a.json, "w") as f:
            json.dump(result, f, indent=2)
    return 0


if __name__ == "__main__":
    sys.exit(main())
