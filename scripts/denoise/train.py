#!/usr/bin/env python3
"""Trains kestrel's denoiser (model.py) on the train clips of make_dataset.py and writes
  weights/denoiser.kdw           the weights (format: docs/denoiser.md)
  weights/denoiser.json          provenance: dataset, command, steps, seed, final losses
  weights/denoiser_loss.png      the loss curve
  tests/data/denoise/            a parity fixture: four small frames and this model's output

    train.py [--data out/denoise_dataset] [--steps 2500] [--seed 1] [--threads 2]
"""
import argparse
import json
import os
import random
import struct
import subprocess
import sys
import time

import numpy as np
import torch
import torch.nn.functional as F

import model as M

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))
import kestrel_nn  # noqa: E402
from kestrel_nn import read_pfm, write_pfm  # noqa: E402

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.normpath(os.path.join(HERE, "..", ".."))


AOVS = [("color", 3), ("albedo", 3), ("normal", 3), ("depth", 1), ("roughness", 1), ("motion", 2)]


def load_frame(d):
    out = []
    for name, c in AOVS:
        a = read_pfm(os.path.join(d, name + ".pfm"))[:, :, :c]
        out.append(np.nan_to_num(a, nan=0.0, posinf=0.0, neginf=0.0))
    return np.concatenate(out, axis=2)  # H, W, 13


def load_clip(root, name, frames, spp=1):
    ins, refs = [], []
    for i in range(frames):
        ins.append(load_frame(os.path.join(root, name, f"spp{spp}", "pfm", f"frame_{i:04d}")))
        refs.append(np.nan_to_num(read_pfm(os.path.join(root, name, "ref", "pfm", f"frame_{i:04d}", "color.pfm"))))
    return np.stack(ins), np.stack(refs)  # T,H,W,13 and T,H,W,3


def split_inputs(t):
    """(B,13,H,W) -> the model's named inputs."""
    return dict(color=t[:, 0:3], albedo=t[:, 3:6], normal=t[:, 6:9], depth=t[:, 9:10], rough=t[:, 10:11],
                motion=t[:, 11:13])


def run_sequence(model, seq, recurrent=True):
    """seq (B,T,13,H,W) -> outputs (B,T,3,H,W)."""
    state, outs = None, []
    for t in range(seq.shape[1]):
        o, state = model(**split_inputs(seq[:, t]), state=state, recurrent=recurrent)
        outs.append(o)
    return torch.stack(outs, dim=1)


def tr(c):
    return torch.log1p(c.clamp(min=0))


def losses(out, ref):
    """ref may be noisy (Noise2Noise, Lehtinen et al. 2018: an independent render of the same
    frames). The spatial term is L1 on log(1 + colour), as for converged references: the
    relative L2 that Noise2Noise prescribes for Monte Carlo targets, (o - r)^2 / (sg(o) +
    0.01)^2, has the target's mean as minimiser but was stopped after 250 steps here (the
    64-spp targets' fireflies on dark pixels gave batches of loss up to 39 against ~1); L1 is
    robust to them at the price of a bias toward the target's median. The gradient-domain and temporal terms are L1 on log(1 + colour) too."""
    a, b = tr(out), tr(ref)
    spatial = (a - b).abs().mean()
    grad = ((a[..., :, 1:] - a[..., :, :-1]) - (b[..., :, 1:] - b[..., :, :-1])).abs().mean() + \
           ((a[..., 1:, :] - a[..., :-1, :]) - (b[..., 1:, :] - b[..., :-1, :])).abs().mean()
    temporal = ((a[:, 1:] - a[:, :-1]) - (b[:, 1:] - b[:, :-1])).abs().mean()
    # Energy: L1 on log(1 + the 8x8 block means of the linear colour). The per-pixel L1 above
    # is minimised by the target's median, which for 1-spp noise is darker than its mean;
    # with the firefly cut the network learned to drop legitimate energy (outputs 9-15 %
    # darker than the references on the held-out families). Block means of a 64-spp target
    # are close to converged, and their mean is the brightness the output must keep.
    B, T = out.shape[:2]
    po = F.avg_pool2d(out.flatten(0, 1).clamp(min=0), 8)
    pr = F.avg_pool2d(ref.flatten(0, 1).clamp(min=0), 8)
    energy = (tr(po) - tr(pr)).abs().mean()
    return spatial, grad, temporal, energy


W_SPATIAL, W_GRAD, W_TEMPORAL, W_ENERGY = 1.0, 0.25, 0.5, 2.0  # defaults of --w-spatial, ... --w-energy
ARCHITECTURE = 4  # model.py's network (1: the filter in log space; 2: unsafe demodulation, no history clamp;
#                   3: the filtered output as state, no firefly clamp)


def export_weights(model, path):
    kestrel_nn.export_kdw(model, path, b"KSTRLDNW", ARCHITECTURE)


def load_weights(model, path, architecture=ARCHITECTURE):
    kestrel_nn.load_kdw(model, path, b"KSTRLDNW", architecture, partial=architecture != ARCHITECTURE)


def fixture_still_frame(ins):
    """The fixture's fourth frame: its third again at the clip's brightness, the camera still
    (no motion), so the history is valid everywhere and long enough (HISTORY_EVIDENCE) for the
    output's last step to take it."""
    f = ins[2].copy()
    f[:, :, 0:3] *= 4
    f[:, :, 11:13] = 0
    return np.concatenate([ins[:3], f[None]])


def write_fixture(model, clip, out_dir):
    """Four frames of a 44 x 30 crop (not a multiple of 8: exercises the padding) from the
    middle of a clip (it must show content), the second 4x brighter and the third 4x darker
    than the clip (both history clamps act), the fourth the third again, still and at the
    clip's brightness (fixture_still_frame); their inputs as PFMs and the model's outputs."""
    T, H, W, _ = clip.shape
    y0, x0 = H // 2 - 15, W // 2 - 22
    ins = clip[:3, y0:y0 + 30, x0:x0 + 44].copy()  # T,H,W,13
    ins[1, :, :, 0:3] *= 4  # a light comes on: the history's lower clamp acts where all is lit
    ins[2, :, :, 0:3] /= 4  # and dims: the upper clamp acts (its 20x20 window, not 12x12)
    write_fixture_frames(model, fixture_still_frame(ins), out_dir)


def write_frame_pfms(d, f, expected):
    """A fixture frame's directory: its inputs f (H,W,13) as the engine's AOV files and the
    model's output expected (H,W,3) as expected.pfm."""
    os.makedirs(d, exist_ok=True)
    write_pfm(os.path.join(d, "color.pfm"), f[:, :, 0:3])
    write_pfm(os.path.join(d, "albedo.pfm"), f[:, :, 3:6])
    write_pfm(os.path.join(d, "normal.pfm"), f[:, :, 6:9])
    write_pfm(os.path.join(d, "depth.pfm"), f[:, :, 9])
    write_pfm(os.path.join(d, "roughness.pfm"), f[:, :, 10])
    write_pfm(os.path.join(d, "motion.pfm"), np.concatenate([f[:, :, 11:13], np.zeros_like(f[:, :, :1])], 2))
    write_pfm(os.path.join(d, "expected.pfm"), expected)


def loss_summary(history, args):
    """The loss weights and the mean of each term over the last 100 steps (fit's history)."""
    tail = np.array(history[-100:])
    return dict(weights=dict(spatial=args.w_spatial, gradient=args.w_grad, temporal=args.w_temporal,
                             energy=args.w_energy),
                final_mean_last_100=dict(total=float(tail[:, 1].mean()), spatial=float(tail[:, 2].mean()),
                                         gradient=float(tail[:, 3].mean()), temporal=float(tail[:, 4].mean()),
                                         energy=float(tail[:, 5].mean())))


def denoise_frames(model, ins):
    """ins (T,H,W,13), any H, W -> the model's outputs (T,3,H,W), as the engine runs it: each
    frame padded to multiples of 8 (edge replication), the output and the state cut back."""
    seq = torch.from_numpy(ins).permute(0, 3, 1, 2)[None].contiguous()
    outs, state = [], None
    with torch.no_grad():
        for t in range(ins.shape[0]):
            x = split_inputs(seq[:, t])
            h, w = x["color"].shape[-2:]
            padded_state = None if state is None else tuple(M.pad8(s) for s in state)
            o, state = model(**{k: M.pad8(v) for k, v in x.items()}, state=padded_state, size=(h, w))
            outs.append(o[0, :, :h, :w])
            state = tuple(s[..., :h, :w] for s in state)
    return torch.stack(outs)


def write_fixture_frames(model, ins, out_dir):
    """ins (T,H,W,13): the frames' inputs as PFMs and the model's outputs (expected.pfm)."""
    os.makedirs(out_dir, exist_ok=True)
    for t, o in enumerate(denoise_frames(model, ins)):
        write_frame_pfms(os.path.join(out_dir, f"frame_{t}"), ins[t], o.permute(1, 2, 0).numpy())


def add_loss_arguments(ap):
    ap.add_argument("--w-spatial", type=float, default=W_SPATIAL)
    ap.add_argument("--w-grad", type=float, default=W_GRAD)
    ap.add_argument("--w-temporal", type=float, default=W_TEMPORAL)
    ap.add_argument("--w-energy", type=float, default=W_ENERGY)


def fit(model, clips, args, every=50):
    """The training loop of both denoisers (this file's and train_rae.py's): Adam with a one-cycle
    schedule peaking at args.lr over args.steps steps, each a batch of args.batch random
    args.crop-pixel crops of whole clips (the recurrence runs over every frame), losses()
    weighted by args.w_*, gradients clipped to norm 1, a checkpoint every `every` steps
    (args.checkpoint; args.resume continues from it). -> the history, one row per step:
    step, total, spatial, gradient, temporal, energy."""
    opt = torch.optim.Adam(model.parameters(), lr=args.lr)
    sched = torch.optim.lr_scheduler.OneCycleLR(opt, max_lr=args.lr, total_steps=args.steps, pct_start=0.1)
    history, first = [], 0
    if args.resume and os.path.exists(args.checkpoint):
        ck = torch.load(args.checkpoint)
        model.load_state_dict(ck["model"]), opt.load_state_dict(ck["opt"]), sched.load_state_dict(ck["sched"])
        history, first = ck["history"], ck["step"]
        random.setstate(ck["random"]), np.random.set_state(ck["numpy"]), torch.set_rng_state(ck["torch"])
        print(f"resumed at step {first}", flush=True)
    t0 = time.time()
    cs = args.crop
    for step in range(first, args.steps):
        if step % every == 0 and step > first:
            os.makedirs(os.path.dirname(args.checkpoint), exist_ok=True)
            torch.save(dict(model=model.state_dict(), opt=opt.state_dict(), sched=sched.state_dict(), history=history,
                            step=step, random=random.getstate(), numpy=np.random.get_state(),
                            torch=torch.get_rng_state()), args.checkpoint + ".tmp")
            os.replace(args.checkpoint + ".tmp", args.checkpoint)
        batch_in, batch_ref = [], []
        for _ in range(args.batch):
            ins, refs = clips[random.randrange(len(clips))]
            T, H, W, _ = ins.shape
            y, x = random.randrange(0, H - cs + 1), random.randrange(0, W - cs + 1)
            batch_in.append(ins[:, y:y + cs, x:x + cs])
            batch_ref.append(refs[:, y:y + cs, x:x + cs])
        seq = torch.from_numpy(np.stack(batch_in)).permute(0, 1, 4, 2, 3).contiguous()
        ref = torch.from_numpy(np.stack(batch_ref)).permute(0, 1, 4, 2, 3).contiguous()
        out = run_sequence(model, seq)
        ls, lg, lt, le = losses(out, ref)
        loss = args.w_spatial * ls + args.w_grad * lg + args.w_temporal * lt + args.w_energy * le
        opt.zero_grad()
        loss.backward()
        norm = torch.nn.utils.clip_grad_norm_(model.parameters(), 1.0)
        if not torch.isfinite(loss) or not torch.isfinite(norm):
            print(f"step {step}: non-finite loss or gradient, step skipped", flush=True)
            sched.step()
            continue
        opt.step()
        sched.step()
        history.append([step, loss.item(), ls.item(), lg.item(), lt.item(), le.item()])
        if step % 50 == 0 or step == args.steps - 1:
            print(f"step {step:5d}  loss {loss.item():.4f}  l1 {ls.item():.4f}  grad {lg.item():.4f}  "
                  f"temporal {lt.item():.4f}  energy {le.item():.4f}  {time.time() - t0:.0f} s", flush=True)
    return history


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--data", default=os.path.join(ROOT, "out", "denoise_dataset"))
    ap.add_argument("--steps", type=int, default=2500)
    ap.add_argument("--batch", type=int, default=4)
    ap.add_argument("--crop", type=int, default=96)
    ap.add_argument("--lr", type=float, default=1e-3)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--out", default=os.path.join(ROOT, "weights"))
    ap.add_argument("--fixture", default=os.path.join(ROOT, "tests", "data", "denoise"))
    ap.add_argument("--fixture-only", action="store_true", help="write the parity fixture from --out's weights and stop")
    ap.add_argument("--fixture-refresh", action="store_true",
                    help="recompute the committed fixture's expected outputs (its inputs kept) from --out's weights "
                         "and stop: after a change to model.py that keeps the weights")
    add_loss_arguments(ap)
    ap.add_argument("--checkpoint", default=os.path.join(ROOT, "out", "denoise_train.ckpt"),
                    help="saved every 100 steps; --resume continues from it")
    ap.add_argument("--resume", action="store_true")
    ap.add_argument("--init", help="start from these weights (architecture 2 or 3: the same tensors but enc1's "
                                   "input for the history length and head's output kappa, which start at 0 and "
                                   "the initial kappa)")
    args = ap.parse_args()
    torch.set_num_threads(args.threads)
    torch.set_flush_denormal(True)  # exp() of large negative arguments: denormals are ~50x slower
    torch.manual_seed(args.seed)
    random.seed(args.seed)
    np.random.seed(args.seed)
    if args.fixture_refresh:
        model = M.Denoiser()
        load_weights(model, os.path.join(args.out, "denoiser.kdw"))
        frames = sorted(d for d in os.listdir(args.fixture) if d.startswith("frame_"))
        ins = np.stack([load_frame(os.path.join(args.fixture, d)) for d in frames])
        write_fixture_frames(model, ins, args.fixture)
        print("refreshed", args.fixture)
        return
    if args.fixture_only:  # the parity fixture from committed weights, without training
        model = M.Denoiser()
        load_weights(model, os.path.join(args.out, "denoiser.kdw"))
        manifest = json.load(open(os.path.join(args.data, "manifest.json")))
        name = sorted(n for n, c in manifest["clips"].items() if c["split"] == "train")[0]
        write_fixture(model, load_clip(args.data, name, 3)[0], args.fixture)
        print("wrote", args.fixture)
        return
    manifest = json.load(open(os.path.join(args.data, "manifest.json")))
    names = sorted(n for n, c in manifest["clips"].items() if c["split"] == "train")
    clips = [load_clip(args.data, n, manifest["clips"][n]["frames"]) for n in names]
    print(f"{len(clips)} train clips: {', '.join(names)}", flush=True)
    model = M.Denoiser()
    if args.init:
        blob = open(args.init, "rb").read()
        init_arch = struct.unpack("<I", blob[12:16])[0]
        load_weights(model, args.init, init_arch)
        if init_arch < 4:  # its alpha weighed a filtered state; an accumulated one may weigh more
            with torch.no_grad():
                model.head.bias[0] += 2.0
        print("initialised from", args.init, flush=True)
    t0 = time.time()
    history = fit(model, clips, args)
    os.makedirs(args.out, exist_ok=True)
    export_weights(model, os.path.join(args.out, "denoiser.kdw"))
    commit = subprocess.run(["git", "-C", ROOT, "rev-parse", "--short", "HEAD"], capture_output=True, text=True).stdout.strip()
    prov = dict(file="denoiser.kdw", architecture=f"kestrel-denoiser-{ARCHITECTURE} (scripts/denoise/model.py)",
                parameters=M.parameter_count(model), framework=f"PyTorch {torch.__version__} (Debian python3-torch)",
                dataset=dict(command=manifest.get("commands", {}).get("train", "python3 scripts/denoise/make_dataset.py --split train"),
                             clips=names, targets=manifest.get("targets", {}).get("train", "references")),
                init=args.init,
                command="python3 scripts/denoise/train.py " + " ".join(sys.argv[1:]), steps=args.steps,
                batch=args.batch, crop=args.crop, seed=args.seed, lr=args.lr, threads=args.threads,
                loss=loss_summary(history, args), seconds=round(time.time() - t0), git=commit)
    init_json = os.path.splitext(args.init)[0] + ".json" if args.init else None
    if init_json and os.path.exists(init_json):  # what the starting weights were trained on
        prov["init_provenance"] = json.load(open(init_json))
    json.dump(prov, open(os.path.join(args.out, "denoiser.json"), "w"), indent=1)
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    h = np.array(history)
    k = max(1, min(25, len(history) // 4))
    smooth = lambda v: np.convolve(v, np.ones(k) / k, mode="valid")
    plt.figure(figsize=(7, 4))
    for i, lab in [(1, "total"), (2, "L1 (log)"), (3, "gradient"), (4, "temporal"), (5, "energy")]:
        plt.plot(h[k - 1:, 0], smooth(h[:, i]), label=lab)
    plt.yscale("log")
    plt.xlabel("step")
    plt.ylabel("loss (moving mean)")
    plt.title(f"kestrel denoiser: {M.parameter_count(model)} parameters, {len(names)} clips")
    plt.legend()
    plt.tight_layout()
    plt.savefig(os.path.join(args.out, "denoiser_loss.png"), dpi=100)
    write_fixture(model, clips[0][0], args.fixture)
    print("wrote", args.out, args.fixture)


if __name__ == "__main__":
    main()
