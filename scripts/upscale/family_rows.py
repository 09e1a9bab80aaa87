#!/usr/bin/env python3
"""Per-family tables from kestrel_upscale_eval's JSON (docs/upscaler/eval.json): for each input
(clean, denoised) and factor, one row per held-out family (its clips averaged) with PSNR dB /
SSIM / tErr / max÷ref (the brightest output pixel over the brightest reference pixel, the worst
clip of the family) per method, and each method's PSNR minus the baseline's.

    family_rows.py [docs/upscaler/eval.json] [--baseline taau] [--methods taau,neural,nsrr-rt,nsrr]
"""
import argparse
import json
from collections import defaultdict

NAMES = {"taau": "TAAU-like", "neural": "neural (learned TAAU)", "bicubic": "bicubic", "bilinear": "bilinear"}


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("json", nargs="?", default="docs/upscaler/eval.json")
    ap.add_argument("--baseline", default="taau")
    ap.add_argument("--methods", default="taau,neural,nsrr-rt,nsrr")
    args = ap.parse_args()
    methods = args.methods.split(",")
    rows = defaultdict(list)  # (input, factor, family, method) -> clip rows
    for r in json.load(open(args.json))["clips"]:
        rows[(r["input"], r["factor"], r["family"], r["method"])].append(r)
    # The shared scenes (their family is the clip's name) after the generated families.
    families = sorted({k[2] for k in rows}, key=lambda f: (f.startswith("test_"), f))
    for inp in sorted({k[0] for k in rows}):
        for f in (2, 4):
            if not any(k[0] == inp and k[1] == f for k in rows):
                continue
            print(f"\n{inp} inputs, {f}×{f} — PSNR dB / SSIM / tErr / max÷ref (worst clip); "
                  f"Δ: PSNR minus {NAMES.get(args.baseline, args.baseline)}'s\n")
            print("| family | " + " | ".join(NAMES.get(m, m) for m in methods) + " | " +
                  " | ".join(f"Δ {m}" for m in methods if m != args.baseline) + " |")
            print("|---" * (1 + 2 * len(methods) - 1) + "|")
            for fam in families:
                cells, psnr = [], {}
                for m in methods:
                    rs = rows.get((inp, f, fam, m))
                    if not rs:
                        cells.append("—")
                        continue
                    mean = {k: sum(r[k] for r in rs) / len(rs) for k in ("psnr", "ssim", "terr")}
                    worst = max(r["max_over_ref_max"] for r in rs)
                    psnr[m] = mean["psnr"]
                    cells.append(f"{mean['psnr']:.2f} / {mean['ssim']:.4f} / {mean['terr']:.4f} / {worst:.2f}")
                deltas = [f"{psnr[m] - psnr[args.baseline]:+.2f}" if m in psnr and args.baseline in psnr else "—"
                          for m in methods if m != args.baseline]
                print(f"| {fam.removeprefix('test_')} | " + " | ".join(cells) + " | " + " | ".join(deltas) + " |")


if __name__ == "__main__":
    main()
