#!/usr/bin/env python3
"""Trains kestrel's `nsrr` upsampler (nsrr.NSRR, after Xiao et al. 2020) or, with --arch rt,
its real-time member `nsrr-rt` (nsrr.NSRRRealTime) on the train clips of make_dataset.py
--families, one network for both factors (f / 4 is an input channel), and writes (NAME:
upscaler_nsrr, or upscaler_nsrr_rt with --arch rt)
  weights/NAME.kdw              the weights (format v1 of docs/denoiser.md, magic KSTRLNSR,
                                architecture 7 (nsrr) or 9 (nsrr-rt))
  weights/NAME.json             provenance: dataset, command, steps, seed, losses, git revision
  weights/NAME_loss.png
  tests/data/NAME/              a parity fixture: four frames of a held-out clip, both factors,
                                and the weights it was made with (weights.kdw)

    train_nsrr.py [--arch full|rt] [--data out/upscale_families] [--steps 3000] [--crop 64]
                  [--batch 4] [--lr 1e-3] [--seed 1] [--threads 2]
                  [--checkpoint out/NAME_train.pt] [--fixture-only]
                  [--history-weights weights/upscaler.kdw] [--init FILE --init-architecture N]

A sample is one output frame and the N = 3 frames before it (fewer at the start of a clip,
the missing ones absent as at the start of a sequence), its inputs the clean point-sampled
frames or, for --denoised-fraction of the samples, the same frames rendered at 1 spp and
denoised (what the real-time loop feeds the upsampler); crops of --crop output pixels,
horizontal mirroring (motion and jitter mirrored too). The history candidate Hy of every frame
(nsrr.history_sequence: the learned TAAU of --history-weights, what the engine runs beside the
network) is computed once per clip over the whole frames, then cropped as the target. Loss: L1
after the evaluation's tone map (ACES fit + sRGB). Adam, one-cycle schedule. --init starts
from other weights (an older architecture's: new input channels at 0, new outputs at their
initial values). The checkpoint (every 100 steps) makes the run resumable: re-running the same
command continues it.
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

import model as M
import nsrr as N
from train import aces_srgb, jitters, load_clip, load_weights, write_fixture_inputs

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))
import kestrel_nn  # noqa: E402
from kestrel_nn import write_pfm  # noqa: E402

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.normpath(os.path.join(HERE, "..", ".."))
# 1, 2: before the bilinear base; 4, 3: a correction of it; 5, 6: the blend without the history
# 8: nsrr-rt with the previous frames' samples at radius 1 (tried, 2026-12-05: 9 ms slower, no better)
ARCHITECTURES = {"full": 7, "rt": 9}
NAMES = {"full": "upscaler_nsrr", "rt": "upscaler_nsrr_rt"}
MAGIC = b"KSTRLNSR"
FIXTURE_CLIP = "test_gallery_1000"


def frames_at(ins, jit, t, n_prev):
    """The window [t, t-1, ..., t-n_prev] of a (B,T,6,h,w) batch as nsrr.NSRR.forward takes it."""
    out = []
    for k in range(n_prev + 1):
        x = ins[:, t - k]
        out.append((x[:, 0:3], x[:, 3:4], x[:, 4:6], jit[:, t - k]))
    return out


def load_history_upsampler(path):
    up = M.Upsampler()
    load_weights(up, path)
    return up.eval()


def write_fixture(model, arch, clip, out_dir, upsampler, name=FIXTURE_CLIP, frames=4, H=48, W=64):
    """Frames 0..3 of a crop of a held-out clip, both factors: inputs and the model's outputs
    (frame t sees frames t, t-1, ..., 0: the start of a sequence; Hy from `upsampler` run over
    the crop, as the engine's learned TAAU runs beside the network)."""
    os.makedirs(out_dir, exist_ok=True)
    ins, _ = clip
    meta = dict(frames=frames, width=W, height=H, clip=name, jitter=[list(M.jitter_of(t)) for t in range(frames)])
    with torch.no_grad():
        for f in (2, 4):
            seq = ins[f][:frames, :, : H // f, : W // f][None]
            jit = jitters(frames)[None]
            hist = N.history_sequence(seq, jit, f, upsampler)
            for t in range(frames):
                x = seq[:, t]
                write_fixture_inputs(x, out_dir, f, t)
                lin, _ = model(frames_at(seq, jit, t, min(t, model.frames)), f, hist[:, t])
                write_pfm(os.path.join(out_dir, f"x{f}_out_{t}.pfm"), lin[0].numpy().transpose(1, 2, 0))
    json.dump(meta, open(os.path.join(out_dir, "fixture.json"), "w"), indent=1)
    kestrel_nn.export_kdw(model, os.path.join(out_dir, "weights.kdw"), MAGIC, arch)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--data", default=os.path.join(ROOT, "out", "upscale_families"))
    ap.add_argument("--steps", type=int, default=3000)
    ap.add_argument("--crop", type=int, default=64)
    ap.add_argument("--batch", type=int, default=4)
    ap.add_argument("--lr", type=float, default=1e-3)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--denoised-fraction", type=float, default=0.5,
                    help="share of samples whose inputs are the denoised 1-spp frames (x2_dn/, x4_dn/)")
    ap.add_argument("--checkpoint", default="", help="default out/NAME_train.pt")
    ap.add_argument("--fixture-only", action="store_true", help="only write the fixture of --weights")
    ap.add_argument("--fixture-clip", default=FIXTURE_CLIP)
    ap.add_argument("--init-only", action="store_true", help="write --weights at the seed's initialisation")
    ap.add_argument("--init", default="", help="start from these weights (an older architecture's: kestrel_nn.load_kdw partial)")
    ap.add_argument("--init-architecture", type=int, default=0, help="the architecture of --init")
    ap.add_argument("--weights", default="", help="default weights/NAME.kdw")
    ap.add_argument("--history-weights", default=os.path.join(ROOT, "weights", "upscaler.kdw"),
                    help="the learned TAAU whose output is the history candidate (the engine's default)")
    ap.add_argument("--bf16", action="store_true", help="train under bf16 autocast (about twice as fast on AMX/AVX-512 bf16)")
    ap.add_argument("--arch", default="full", choices=sorted(ARCHITECTURES),
                    help="full: nsrr (Xiao et al.'s network); rt: nsrr-rt, the real-time member")
    args = ap.parse_args()
    name = NAMES[args.arch]
    args.weights = args.weights or os.path.join(ROOT, "weights", name + ".kdw")
    args.checkpoint = args.checkpoint or os.path.join(ROOT, "out", name + "_train.pt")
    ARCHITECTURE = ARCHITECTURES[args.arch]
    if args.crop % 16:
        sys.exit(f"--crop {args.crop}: must be a multiple of 16 (4x4 inputs, two poolings)")
    torch.set_num_threads(args.threads)
    torch.set_flush_denormal(True)
    torch.manual_seed(args.seed)
    rng = random.Random(args.seed)
    manifest = json.load(open(os.path.join(args.data, "manifest.json")))
    fixture_dir = os.path.join(ROOT, "tests", "data", name.replace("upscaler", "upscale"))
    model = N.NSRR() if args.arch == "full" else N.NSRRRealTime()
    if args.init_only:  # the seed's initialisation (what the parity fixture may be made with)
        os.makedirs(os.path.dirname(args.weights), exist_ok=True)
        kestrel_nn.export_kdw(model, args.weights, MAGIC, ARCHITECTURE)
        print(f"wrote {args.weights}")
        return
    if args.fixture_only:
        kestrel_nn.load_kdw(model, args.weights, MAGIC, ARCHITECTURE)
        write_fixture(model, ARCHITECTURE, load_clip(args.data, args.fixture_clip, 4), fixture_dir,
                      load_history_upsampler(args.history_weights), args.fixture_clip)
        print(f"wrote {fixture_dir}")
        return
    if args.init:
        kestrel_nn.load_kdw(model, args.init, MAGIC, args.init_architecture, partial=True)
        print(f"started from {args.init} (architecture {args.init_architecture})", flush=True)
    names = sorted(n for n, c in manifest["clips"].items() if c["split"] == "train")
    clips = [load_clip(args.data, n, manifest["clips"][n]["frames"]) for n in names]
    # The same frames at 1 spp through the denoiser (make_dataset.py --denoised), the same targets.
    denoised = [load_clip(args.data, n, manifest["clips"][n]["frames"], "_dn")[0] if manifest["clips"][n].get("denoised")
                else None for n in names]
    if args.denoised_fraction > 0 and not any(d is not None for d in denoised):
        sys.exit(f"{args.data}: no denoised inputs (make_dataset.py --denoised); pass --denoised-fraction 0")
    # The depth scale of every frame, from the whole frame (what inference sees).
    scales = [{f: N.depth_scale(ins[f][:, 3:4]) for f in (2, 4)} for ins, _ in clips]
    # Hy of every frame, clean and denoised inputs (the learned TAAU over the whole clip).
    upsampler = load_history_upsampler(args.history_weights)
    t_hist = time.time()
    def histories(ins):
        return {f: N.history_sequence(ins[f][None], jitters(ins[f].shape[0])[None], f, upsampler)[0] for f in (2, 4)}
    hist = [histories(ins) for ins, _ in clips]
    hist_dn = [histories(d) if d is not None else None for d in denoised]
    print(f"history candidates of {len(clips)} clips in {time.time() - t_hist:.0f} s", flush=True)
    print(f"{len(clips)} training clips: {', '.join(names)}", flush=True)
    params = sum(p.numel() for p in model.parameters())
    print(f"{params} parameters", flush=True)
    opt = torch.optim.Adam(model.parameters(), lr=args.lr)
    sched = torch.optim.lr_scheduler.OneCycleLR(opt, max_lr=args.lr, total_steps=args.steps, pct_start=0.05)
    history, start, seconds = [], 0, 0.0
    if os.path.exists(args.checkpoint):
        ck = torch.load(args.checkpoint)
        if ck["args"] == {k: v for k, v in vars(args).items() if k not in ("threads",)}:
            model.load_state_dict(ck["model"]), opt.load_state_dict(ck["opt"]), sched.load_state_dict(ck["sched"])
            history, start, seconds = ck["history"], ck["step"], ck["seconds"]
            rng.setstate(ck["rng"]), torch.set_rng_state(ck["torch_rng"])
            print(f"resumed at step {start}", flush=True)
    t_start = time.time() - seconds
    c = args.crop
    for step in range(start, args.steps):
        f = 2 if step % 2 == 0 else 4
        # Fewer than N previous frames in 1 batch of 8: the start of a sequence.
        n_prev = rng.randint(0, model.frames - 1) if rng.random() < 0.125 else model.frames
        seqs, refs, jits, ss, hs = [], [], [], [], []
        for _ in range(args.batch):
            k = rng.randrange(len(clips))
            ins, ref = clips[k]
            hk = hist[k]
            if denoised[k] is not None and rng.random() < args.denoised_fraction:
                ins, hk = denoised[k], hist_dn[k]
            T, _, Hf, Wf = ref.shape
            t = rng.randint(n_prev, T - 1)
            cx = rng.randrange(0, (Wf - c) // 4 + 1) * 4
            cy = rng.randrange(0, (Hf - c) // 4 + 1) * 4
            lx, ly, lc = cx // f, cy // f, c // f
            seq = ins[f][t - n_prev:t + 1, :, ly:ly + lc, lx:lx + lc]
            r = ref[t, :, cy:cy + c, cx:cx + c]
            hy = hk[f][t, :, cy:cy + c, cx:cx + c]
            jit = jitters(n_prev + 1, t - n_prev)
            if rng.random() < 0.5:  # mirror: flips the horizontal motion and the jitter
                seq = torch.flip(seq, [3]).clone()
                seq[:, 4] = -seq[:, 4]
                r = torch.flip(r, [2])
                hy = torch.flip(hy, [2])
                jit[:, 0] = 1.0 - jit[:, 0]
            seqs.append(seq), refs.append(r), jits.append(jit), ss.append(scales[k][f][t]), hs.append(hy)
        seq, ref, jit, s, hy = torch.stack(seqs), torch.stack(refs), torch.stack(jits), torch.stack(ss), torch.stack(hs)
        with torch.autocast("cpu", dtype=torch.bfloat16, enabled=args.bf16):
            lin, _ = model(frames_at(seq, jit, n_prev, n_prev), f, hy, scale=s)
        lin = lin.float()
        m = 4
        loss = torch.mean(torch.abs(aces_srgb(lin) - aces_srgb(ref))[:, :, m:-m, m:-m])
        opt.zero_grad()
        loss.backward()
        opt.step()
        sched.step()
        history.append((step, f, loss.item()))
        if step % 25 == 0 or step == args.steps - 1:
            print(f"step {step:5d} x{f} prev {n_prev} l1 {loss.item():.5f}  {time.time() - t_start:.0f} s", flush=True)
        if (step + 1) % 100 == 0 and step + 1 < args.steps:
            os.makedirs(os.path.dirname(args.checkpoint), exist_ok=True)
            torch.save(dict(args={k: v for k, v in vars(args).items() if k not in ("threads",)}, model=model.state_dict(),
                            opt=opt.state_dict(), sched=sched.state_dict(), history=history, step=step + 1,
                            seconds=time.time() - t_start, rng=rng.getstate(), torch_rng=torch.get_rng_state()),
                       args.checkpoint + ".tmp")
            os.replace(args.checkpoint + ".tmp", args.checkpoint)
    os.makedirs(os.path.dirname(args.weights), exist_ok=True)
    kestrel_nn.export_kdw(model, args.weights, MAGIC, ARCHITECTURE)
    tail = history[-100:]
    prov = dict(
        network=(f"kestrel {'nsrr' if args.arch == 'full' else 'nsrr-rt'} upsampler, architecture {ARCHITECTURE} "
                 f"(scripts/upscale/nsrr.py {type(model).__name__}; after Xiao et al. 2020)"),
        parameters=params,
        dataset=os.path.relpath(args.data, ROOT),
        history=dict(weights=os.path.relpath(args.history_weights, ROOT),
                     fnv1a=f"{kestrel_nn.fnv1a(open(args.history_weights, 'rb').read()):016x}"),
        dataset_commands=manifest.get("commands", {}),
        clips=names,
        command="python3 scripts/upscale/train_nsrr.py " + " ".join(sys.argv[1:]),
        init=dict(weights=args.init, architecture=args.init_architecture,
                  fnv1a=f"{kestrel_nn.fnv1a(open(args.init, 'rb').read()):016x}") if args.init else None,
        loss="L1 after ACES fit + sRGB", denoised_fraction=args.denoised_fraction, steps=args.steps, crop=args.crop, batch=args.batch, lr=args.lr, seed=args.seed,
        final_l1_x2=float(np.mean([h[2] for h in tail if h[1] == 2])),
        final_l1_x4=float(np.mean([h[2] for h in tail if h[1] == 4])),
        seconds=round(time.time() - t_start), torch=torch.__version__,
        git=subprocess.run(["git", "-C", ROOT, "rev-parse", "--short", "HEAD"], capture_output=True, text=True).stdout.strip(),
    )
    json.dump(prov, open(os.path.splitext(args.weights)[0] + ".json", "w"), indent=1)
    kestrel_nn.plot_loss(history, os.path.splitext(args.weights)[0] + "_loss.png", 25)
    if FIXTURE_CLIP in manifest["clips"]:
        write_fixture(model, ARCHITECTURE, load_clip(args.data, FIXTURE_CLIP, 4), fixture_dir, upsampler)
    print(f"wrote {args.weights}")


if __name__ == "__main__":
    main()
