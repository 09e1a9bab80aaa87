#!/usr/bin/env python3
"""model.py's denoiser on the test clips of make_dataset.py, in PyTorch: a quick A/B of weights
files (or of changes to model.py) before the engine has them. PSNR and tErr as kestrel_denoise_eval
computes them (tone-mapped: exposure 0, ACES fit, sRGB), per clip and per family, at one spp.

    eval_torch.py --data out/denoise_families WEIGHTS.kdw [WEIGHTS2.kdw ...] [--spp 1] [--frames 16]

The engine's figures (kestrel_denoise_eval) are the ones to quote; this is for choosing.
"""
import argparse
import json
import os
import sys

import numpy as np
import torch

import model as M
import train as T
from kestrel_nn import aces_srgb


def psnr(a, b):
    mse = float(((a - b) ** 2).mean())
    return 10 * np.log10(1.0 / max(mse, 1e-12))


def load_model(path):
    model = M.Denoiser()
    T.load_weights(model, path)
    return model.eval()


def family(name):
    parts = name.split("_")[1:]  # test_<family>_<seed> or test_<scene>
    return "_".join(parts[:-1]) if parts[-1].isdigit() else "_".join(parts)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("weights", nargs="+")
    ap.add_argument("--data", default=os.path.join(T.ROOT, "out", "denoise_families"))
    ap.add_argument("--spp", type=int, default=1)
    ap.add_argument("--frames", type=int, default=16)
    ap.add_argument("--threads", type=int, default=2)
    args = ap.parse_args()
    torch.set_num_threads(args.threads)
    torch.set_flush_denormal(True)
    manifest = json.load(open(os.path.join(args.data, "manifest.json")))
    names = sorted(n for n, c in manifest["clips"].items() if c["split"] == "test")
    models = [load_model(w) for w in args.weights]
    per = {w: {} for w in args.weights}
    for name in names:
        frames = min(args.frames, manifest["clips"][name]["frames"])
        ins, refs = T.load_clip(args.data, name, frames, args.spp)
        ref = aces_srgb(torch.from_numpy(refs).permute(0, 3, 1, 2))
        row = []
        for w, model in zip(args.weights, models):
            out = aces_srgb(T.denoise_frames(model, ins))
            p = float(np.mean([psnr(out[t], ref[t]) for t in range(frames)]))
            terr = float(((out[1:] - out[:-1]) - (ref[1:] - ref[:-1])).abs().mean())
            per[w].setdefault(family(name), []).append((p, terr))
            row.append(f"{p:6.2f} dB  tErr {terr:.4f}")
        print(f"{name:28s} " + "  |  ".join(row), flush=True)
    print("\nper family (PSNR / tErr), " + " | ".join(os.path.basename(w) for w in args.weights))
    for fam in sorted(per[args.weights[0]]):
        cells = []
        for w in args.weights:
            v = np.array(per[w][fam])
            cells.append(f"{v[:, 0].mean():6.2f} / {v[:, 1].mean():.4f}")
        print(f"{fam:16s} " + "  |  ".join(cells))
    sys.stdout.flush()


if __name__ == "__main__":
    main()
