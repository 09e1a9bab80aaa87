#!/usr/bin/env python3
"""Trains kestrel's `rae` denoiser (rae.py, Chaitanya et al. 2017) on the same train clips,
targets and loss as the fast denoiser (train.py) and writes
  weights/denoiser_rae.kdw       the weights (format v1, docs/denoiser.md; magic KSTRLRAE)
  weights/denoiser_rae.json      provenance: dataset, command, steps, seed, final losses
  weights/denoiser_rae_loss.png  the loss curve
  tests/data/denoise_rae/        a parity fixture: three small frames and this model's output

    train_rae.py [--data out/denoise_families] [--steps 3000] [--seed 1] [--threads 2]
                 [--init weights/denoiser_rae.kdw]   (a warm restart from earlier weights)

Resumable: a checkpoint every 50 steps, --resume continues from it (train.fit, the fast
denoiser's training loop).
"""
import argparse
import json
import os
import random
import subprocess
import sys
import time

import numpy as np
import torch

import rae as R
import train as T

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))
import kestrel_nn  # noqa: E402

ROOT = T.ROOT
MAGIC, ARCHITECTURE = b"KSTRLRAE", 1


def write_fixture(model, clip, out_dir):
    """Three frames of a 44 x 30 crop (not a multiple of 16: exercises the padding) from the
    middle of a clip, the third 4x brighter (the recurrent state meets a change), their
    inputs as PFMs and the model's outputs."""
    _, H, W, _ = clip.shape
    y0, x0 = H // 2 - 15, W // 2 - 22
    ins = clip[:3, y0:y0 + 30, x0:x0 + 44].copy()
    ins[2, :, :, 0:3] *= 4
    seq = torch.from_numpy(ins).permute(0, 3, 1, 2)[None].contiguous()
    with torch.no_grad():
        out = T.run_sequence(model, seq)
    for t in range(ins.shape[0]):
        T.write_frame_pfms(os.path.join(out_dir, f"frame_{t}"), ins[t], out[0, t].permute(1, 2, 0).numpy())


def init_provenance(path):
    """What a warm start began from: the weights' own provenance (the .json beside them), nested."""
    if not path:
        return None
    prov = os.path.splitext(path)[0] + ".json"
    return dict(file=os.path.basename(path), provenance=json.load(open(prov)) if os.path.exists(prov) else None)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--data", default=os.path.join(ROOT, "out", "denoise_families"))
    ap.add_argument("--steps", type=int, default=3000)
    ap.add_argument("--batch", type=int, default=4)
    ap.add_argument("--crop", type=int, default=64)
    ap.add_argument("--lr", type=float, default=5e-4)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--out", default=os.path.join(ROOT, "weights"))
    ap.add_argument("--fixture", default=os.path.join(ROOT, "tests", "data", "denoise_rae"))
    ap.add_argument("--fixture-only", action="store_true", help="write the parity fixture from --out's weights and stop")
    T.add_loss_arguments(ap)
    ap.add_argument("--checkpoint", default=os.path.join(ROOT, "out", "denoise_rae_train.ckpt"))
    ap.add_argument("--resume", action="store_true")
    ap.add_argument("--init", help="start from these weights (a denoiser_rae.kdw): a warm restart of the "
                                   "schedule, for training longer than one run")
    args = ap.parse_args()
    torch.set_num_threads(args.threads)
    torch.set_flush_denormal(True)
    torch.manual_seed(args.seed)
    random.seed(args.seed)
    np.random.seed(args.seed)
    manifest = json.load(open(os.path.join(args.data, "manifest.json")))
    names = sorted(n for n, c in manifest["clips"].items() if c["split"] == "train")
    model = R.RAE()
    weights = os.path.join(args.out, "denoiser_rae.kdw")
    if args.fixture_only:
        kestrel_nn.load_kdw(model, weights, MAGIC, ARCHITECTURE)
        write_fixture(model, T.load_clip(args.data, names[0], 3)[0], args.fixture)
        print("wrote", args.fixture)
        return
    if args.init and not (args.resume and os.path.exists(args.checkpoint)):
        kestrel_nn.load_kdw(model, args.init, MAGIC, ARCHITECTURE)
        print("initialised from", args.init, flush=True)
    clips = [T.load_clip(args.data, n, manifest["clips"][n]["frames"]) for n in names]
    print(f"{len(clips)} train clips, {R.parameter_count(model)} parameters", flush=True)
    t0 = time.time()
    history = T.fit(model, clips, args)
    os.makedirs(args.out, exist_ok=True)
    kestrel_nn.export_kdw(model, weights, MAGIC, ARCHITECTURE)
    commit = subprocess.run(["git", "-C", ROOT, "rev-parse", "--short", "HEAD"], capture_output=True,
                            text=True).stdout.strip()
    prov = dict(file="denoiser_rae.kdw",
                architecture=f"kestrel-rae-{ARCHITECTURE} (scripts/denoise/rae.py), channels {list(R.CHANNELS)}",
                parameters=R.parameter_count(model), framework=f"PyTorch {torch.__version__} (Debian python3-torch)",
                dataset=dict(command=manifest.get("commands", {}).get("train"), clips=names,
                             targets=manifest.get("targets", {}).get("train", "references")),
                command="python3 scripts/denoise/train_rae.py " + " ".join(sys.argv[1:]), steps=args.steps,
                init=init_provenance(args.init),
                batch=args.batch, crop=args.crop, seed=args.seed, lr=args.lr, threads=args.threads,
                loss=T.loss_summary(history, args), seconds=round(time.time() - t0), git=commit)
    json.dump(prov, open(os.path.join(args.out, "denoiser_rae.json"), "w"), indent=1)
    kestrel_nn.plot_loss([(h[0], 1, h[1]) for h in history], os.path.join(args.out, "denoiser_rae_loss.png"),
                         max(1, min(25, len(history) // 4)), label="total loss")
    write_fixture(model, clips[0][0], args.fixture)
    print("wrote", weights, args.fixture)


if __name__ == "__main__":
    main()
