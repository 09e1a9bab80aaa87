#!/usr/bin/env python3
"""Trains kestrel's temporal upsampler (model.py) on the train clips of make_dataset.py, one
network for both factors (the factor is an input), and writes
  weights/upscaler.kdw          the weights (format: docs/upscaler.md)
  weights/upscaler.json         provenance: dataset, command, steps, seed, TAAU constants, losses
  weights/upscaler_loss.png     the loss curve
  tests/data/upscale/           a parity fixture: three small frames and this model's output

    train.py [--data out/upscale_dataset] [--steps 1200] [--seed 1] [--threads 2]
             [--tune-taau [--taau-grid A;G;K]] [--loss aces|y] [--fixture-only]
             [--fixture-refresh] [--denoised-fraction P]

--tune-taau first picks the TAAU-like baseline's constants (a, gamma, kappa) on the training
clips (grid search, L1 in the tone-mapped space) and writes them into the provenance; the
network starts from them, so it starts as the baseline.
"""
import argparse
import itertools
import json
import math
import os
import random
import subprocess
import sys
import time

import numpy as np
import torch

import model as M

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))
import kestrel_nn  # noqa: E402
from kestrel_nn import aces_srgb, read_pfm, write_pfm  # noqa: E402

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.normpath(os.path.join(HERE, "..", ".."))
ARCHITECTURE = 1
MAGIC = b"KSTRLUPW"


def load_clip(root, name, frames, suffix=""):
    """-> {2: (T,6,h,w), 4: (T,6,h,w)} inputs (colour, depth, motion) and the (T,3,H,W) targets.
    suffix "_dn": the denoised 1-spp inputs (make_dataset.py --denoised) instead of the clean ones."""
    ins = {}
    for f in (2, 4):
        seq = []
        for i in range(frames):
            d = os.path.join(root, name, f"x{f}{suffix}", "pfm", f"frame_{i:04d}")
            c = read_pfm(os.path.join(d, "color.pfm"))
            z = read_pfm(os.path.join(d, "depth.pfm"))[:, :, :1]
            m = read_pfm(os.path.join(d, "motion.pfm"))[:, :, :2]
            seq.append(np.concatenate([c, z, m], 2).transpose(2, 0, 1))
        ins[f] = torch.from_numpy(np.stack(seq))
    ref = np.stack([read_pfm(os.path.join(root, name, "full", "pfm", f"frame_{i:04d}", "color.pfm")).transpose(2, 0, 1)
                    for i in range(frames)])
    return ins, torch.from_numpy(ref)


def jitters(frames, start=0):
    return torch.tensor([M.jitter_of(start + t) for t in range(frames)], dtype=torch.float32)


def loss_of(outs, refs, margin=0, space="y"):
    """L1 plus a temporal term: outs in y, refs (B,T,3,H,W) linear; space "aces" compares
    after the evaluation's tone map."""
    if space == "aces":
        outs = [aces_srgb(M.from_y(o)) for o in outs]
        ty = [aces_srgb(refs[:, t]) for t in range(refs.shape[1])]
    else:
        ty = [M.to_y(refs[:, t]) for t in range(refs.shape[1])]
    sl = slice(margin, -margin if margin else None)
    l1 = sum(torch.mean(torch.abs(o - r)[:, :, sl, sl]) for o, r in zip(outs, ty)) / len(outs)
    tl = sum(torch.mean(torch.abs((outs[t] - outs[t - 1]) - (ty[t] - ty[t - 1]))[:, :, sl, sl])
             for t in range(1, len(outs))) / max(1, len(outs) - 1)
    return l1, tl


def export_weights(model, path):
    kestrel_nn.export_kdw(model, path, MAGIC, ARCHITECTURE)


def load_weights(model, path):
    kestrel_nn.load_kdw(model, path, MAGIC, ARCHITECTURE)


def tune_taau(clips, grid, space):
    """Grid search of the baseline's constants on the training clips (the training loss's L1)."""
    best = None
    with torch.no_grad():
        for a, g, k in itertools.product(*grid):
            c = dict(a=a, gamma=g, kappa=k)
            total = 0.0
            for ins, ref in clips:
                T = ref.shape[0]
                for f in (2, 4):
                    outs = M.run_sequence(ins[f][None], jitters(T)[None], f, constants=c)
                    total += loss_of(outs, ref[None], space=space)[0].item()
            print(f"taau a={a} gamma={g} kappa={k}: {total / (2 * len(clips)):.5f}", flush=True)
            if best is None or total < best[0]:
                best = (total, c)
    return best[1]


def write_fixture_inputs(x, out_dir, f, t):
    """Frame t of a fixture (x: (1,6,h,w) colour, depth, motion) as x{f}_{color,depth,motion}_{t}.pfm."""
    for name, sl in (("color", slice(0, 3)), ("depth", slice(3, 4)), ("motion", slice(4, 6))):
        a = x[0, sl].numpy().transpose(1, 2, 0)
        if a.shape[2] == 2:
            a = np.concatenate([a, np.zeros_like(a[:, :, :1])], 2)
        write_pfm(os.path.join(out_dir, f"x{f}_{name}_{t}.pfm"), a)


def write_fixture(model, clip, out_dir, frames=3, H=48, W=64):
    """A crop of a held-out clip, both factors: inputs, jitter and the model's outputs."""
    os.makedirs(out_dir, exist_ok=True)
    ins, _ = clip
    meta = dict(frames=frames, width=W, height=H, jitter=[list(M.jitter_of(t)) for t in range(frames)])
    with torch.no_grad():
        for f in (2, 4):
            seq = ins[f][:frames, :, : H // f, : W // f][None]
            state = None
            for t in range(frames):
                x = seq[:, t]
                write_fixture_inputs(x, out_dir, f, t)
                lin, _, state = M.step(x[:, 0:3], x[:, 3:4], x[:, 4:6], jitters(frames)[None, t], f, state, model=model)
                write_pfm(os.path.join(out_dir, f"x{f}_out_{t}.pfm"), lin[0].numpy().transpose(1, 2, 0))
    json.dump(meta, open(os.path.join(out_dir, "fixture.json"), "w"), indent=1)


def refresh_fixture(model, out_dir):
    """Recomputes the fixture's outputs from its own inputs (after a change of model.py's
    function; the inputs, a crop of a clip no longer on disk, stay as they are)."""
    meta = json.load(open(os.path.join(out_dir, "fixture.json")))
    with torch.no_grad():
        for f in (2, 4):
            state = None
            for t in range(meta["frames"]):
                x = [torch.from_numpy(read_pfm(os.path.join(out_dir, f"x{f}_{name}_{t}.pfm"))[:, :, :c].copy())
                     .permute(2, 0, 1)[None].float() for name, c in (("color", 3), ("depth", 1), ("motion", 2))]
                lin, _, state = M.step(x[0], x[1], x[2], jitters(meta["frames"])[None, t], f, state, model=model)
                write_pfm(os.path.join(out_dir, f"x{f}_out_{t}.pfm"), lin[0].numpy().transpose(1, 2, 0))


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--data", default=os.path.join(ROOT, "out", "upscale_dataset"))
    ap.add_argument("--steps", type=int, default=1200)
    ap.add_argument("--crop", type=int, default=96)
    ap.add_argument("--batch", type=int, default=4)
    ap.add_argument("--frames", type=int, default=8)
    ap.add_argument("--lr", type=float, default=2e-3)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--tune-taau", action="store_true")
    ap.add_argument("--taau-grid", default="0.25,0.35,0.5;0.5,0.75,1.0;0.0625,0.125",
                    help="a values; gamma values; kappa values")
    ap.add_argument("--loss", default="aces", choices=["aces", "y"],
                    help="L1 on the evaluation's tone map (ACES fit + sRGB) or in the network's y space")
    ap.add_argument("--denoised-fraction", type=float, default=0.0,
                    help="share of the samples taken from the clips' denoised 1-spp inputs (make_dataset.py --denoised)")
    ap.add_argument("--fixture-only", action="store_true")
    ap.add_argument("--fixture-refresh", action="store_true",
                    help="recompute the fixture's outputs from its inputs with --weights, then stop")
    ap.add_argument("--weights", default=os.path.join(ROOT, "weights", "upscaler.kdw"))
    args = ap.parse_args()
    torch.set_num_threads(args.threads)
    torch.set_flush_denormal(True)
    torch.manual_seed(args.seed)
    random.seed(args.seed)
    fixture_dir = os.path.join(ROOT, "tests", "data", "upscale")
    if args.fixture_refresh:
        model = M.Upsampler()
        load_weights(model, args.weights)
        refresh_fixture(model, fixture_dir)
        print(f"refreshed {fixture_dir}")
        return
    manifest = json.load(open(os.path.join(args.data, "manifest.json")))
    if args.fixture_only:
        model = M.Upsampler()
        load_weights(model, args.weights)
        name = "test_room_1000"
        write_fixture(model, load_clip(args.data, name, 3), fixture_dir)
        print(f"wrote {fixture_dir}")
        return
    names = [n for n, c in manifest["clips"].items() if c["split"] == "train"]
    clips = [load_clip(args.data, n, manifest["clips"][n]["frames"]) for n in names]
    print(f"{len(clips)} training clips: {', '.join(names)}", flush=True)
    # The same clips' denoised 1-spp inputs (make_dataset.py --denoised), same targets: what
    # the real-time loop feeds the upsampler.
    denoised = []
    if args.denoised_fraction > 0:
        denoised = [(load_clip(args.data, n, manifest["clips"][n]["frames"], "_dn")[0], c[1])
                    for n, c in zip(names, clips) if manifest["clips"][n].get("denoised")]
        if not denoised:
            sys.exit(f"--denoised-fraction: no clip of {args.data} has denoised inputs (make_dataset.py --denoised)")
        print(f"{len(denoised)} clips with denoised inputs, used for {args.denoised_fraction:.0%} of the samples", flush=True)
    constants = dict(M.TAAU)
    if args.tune_taau:
        grid = [tuple(float(v) for v in part.split(",")) for part in args.taau_grid.split(";")]
        constants = tune_taau(clips, grid, args.loss)
        print(f"TAAU-like constants: {constants}", flush=True)
    model = M.Upsampler()
    model.set_constants(**constants)
    params = sum(p.numel() for p in model.parameters())
    print(f"{params} parameters", flush=True)
    opt = torch.optim.Adam(model.parameters(), lr=args.lr)
    sched = torch.optim.lr_scheduler.OneCycleLR(opt, max_lr=args.lr, total_steps=args.steps, pct_start=0.1)
    history = []
    t_start = time.time()
    for step in range(args.steps):
        f = 2 if step % 2 == 0 else 4
        seqs, refs, jits = [], [], []
        for _ in range(args.batch):
            ins, ref = random.choice(denoised if denoised and random.random() < args.denoised_fraction else clips)
            T, _, Hf, Wf = ref.shape
            n = min(args.frames, T)
            t0 = random.randint(0, T - n)
            cx = random.randrange(0, (Wf - args.crop) // 4 + 1) * 4
            cy = random.randrange(0, (Hf - args.crop) // 4 + 1) * 4
            lx, ly, lc = cx // f, cy // f, args.crop // f
            seq = ins[f][t0:t0 + n, :, ly:ly + lc, lx:lx + lc]
            r = ref[t0:t0 + n, :, cy:cy + args.crop, cx:cx + args.crop]
            if random.random() < 0.5:  # mirror: flips the horizontal motion and the jitter
                seq = torch.flip(seq, [3]).clone()
                seq[:, 4] = -seq[:, 4]
                r = torch.flip(r, [3])
                jit = jitters(n, t0)
                jit[:, 0] = 1.0 - jit[:, 0]
                # mirrored sample positions: pixel i of the flipped frame sits at lc-1-i' + (1 - jx)
            else:
                jit = jitters(n, t0)
            seqs.append(seq), refs.append(r), jits.append(jit)
        seq, ref, jit = torch.stack(seqs), torch.stack(refs), torch.stack(jits)
        outs = M.run_sequence(seq, jit, f, model=model)
        l1, tl = loss_of(outs, ref, margin=8, space=args.loss)
        loss = l1 + 0.25 * tl
        opt.zero_grad()
        loss.backward()
        opt.step()
        sched.step()
        history.append((step, f, l1.item(), tl.item()))
        if step % 25 == 0 or step == args.steps - 1:
            print(f"step {step:5d} x{f} l1 {l1.item():.5f} temporal {tl.item():.5f}  {time.time() - t_start:.0f} s", flush=True)
    os.makedirs(os.path.dirname(args.weights), exist_ok=True)
    export_weights(model, args.weights)
    tail = history[-100:]
    prov = dict(
        network="kestrel temporal upsampler, architecture 1 (scripts/upscale/model.py)",
        parameters=params,
        dataset=os.path.relpath(args.data, ROOT),
        clips=names,
        command="python3 scripts/upscale/train.py " + " ".join(sys.argv[1:]),
        denoised_fraction=args.denoised_fraction,
        loss=args.loss, steps=args.steps, crop=args.crop, batch=args.batch, frames=args.frames, lr=args.lr, seed=args.seed,
        taau_constants=constants,
        final_l1=float(np.mean([h[2] for h in tail])), final_temporal=float(np.mean([h[3] for h in tail])),
        seconds=round(time.time() - t_start), torch=torch.__version__,
        git=subprocess.run(["git", "-C", ROOT, "rev-parse", "--short", "HEAD"], capture_output=True, text=True).stdout.strip(),
    )
    json.dump(prov, open(os.path.splitext(args.weights)[0] + ".json", "w"), indent=1)
    kestrel_nn.plot_loss(history, os.path.splitext(args.weights)[0] + "_loss.png", 20)
    test = [n for n, c in manifest["clips"].items() if n == "test_room_1000"]
    if test:
        write_fixture(model, load_clip(args.data, test[0], 3), fixture_dir)
    else:  # another dataset (the families): the committed fixture's inputs, this model's outputs
        refresh_fixture(model, fixture_dir)
    print(f"wrote {args.weights}")


if __name__ == "__main__":
    main()
