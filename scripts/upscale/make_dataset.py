#!/usr/bin/env python3
"""The upsampler's dataset, rendered by `kestrel render-sequence`. Per clip, the same camera
path and frames at three resolutions:
  - full/: the target, --res (default 320x180), --ref-spp samples spread over each pixel
    (antialiased, as the high-resolution frame should look);
  - x2/, x4/: the inputs at 1/2 and 1/4 of the resolution, point-sampled at the frame's
    Halton jitter (--fixed-jitter) with --in-spp samples: the clean low-resolution frames a
    real-time renderer would produce after denoising, with depth and motion vectors;
  - x2_dn/, x4_dn/ (--denoised METHOD): the same frames at 1 spp through kestrel's denoiser,
    what the real-time loop actually feeds the upsampler.
Clips: shared scenes (turntables) and procedural rooms (../denoise/procedural.py). The test
clips' scenes are never used in training: Sponza, the Lamborghini and rooms with seeds >= 1000.

    make_dataset.py [--out out/upscale_dataset] [--split train|test|all] [--res 320x180]
                    [--frames 12] [--test-frames 16] [--ref-spp 256] [--test-ref-spp 384]
                    [--in-spp 128] [--rooms 8] [--max-depth 3] [--clamp 8]

With --families (the dataset of the nsrr upsampler and of issue 19's evaluation): the training
clips are the TRAIN families of ../denoise/families.py (--seeds each), the test clips the
HELDOUT families (--test-seeds each, never seen in training) and the shared Sponza and
Lamborghini:

    make_dataset.py --families --out out/upscale_families --ref-spp 64 --test-ref-spp 256 \
                    --in-spp 64 --denoised neural

Each family's own light flags (sun, sky, lights file) are kept; --max-depth and --clamp apply
to inputs and targets alike.

Re-running skips finished clips (a clip is finished when its manifest entry exists); with
--denoised, a finished clip rendered without it gets its denoised inputs added.
"""
import argparse
import json
import os
import subprocess
import sys
import time

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))
import kestrel_mpi  # noqa: E402

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "denoise"))
import families  # noqa: E402

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.normpath(os.path.join(HERE, "..", ".."))
SCENES = os.path.normpath(os.path.join(ROOT, "..", "shared", "scenes"))


def family_clips(args):
    return families.dataset_clips(args.seeds, args.test_seeds, [
        dict(name="test_sponza", scene=os.path.join(SCENES, "dabrovic_sponza/sponza.obj"),
             path=os.path.join(ROOT, "data/paths/sponza_short.json")),
        dict(name="test_lamborghini", scene=os.path.join(SCENES, "lamborghini/lamborghini.obj"), path="orbit:32")])


def clips(args):
    if args.families:
        return family_clips(args)
    out = []
    shared = [
        ("cornell_box", "cornell_box/cornell_box.obj", "orbit:24"),
        ("teapot", "teapot/teapot.obj", "orbit:40"),
        ("bunny", "stanford_bunny/stanford_bunny.obj", "orbit:40"),
        ("box_animated", "gltf_box_animated/BoxAnimated.gltf", os.path.join(ROOT, "data/paths/box_animated_orbit.json")),
        ("flight_helmet", "gltf_flight_helmet/FlightHelmet.gltf", "orbit:40"),
    ]
    for name, scene, path in shared:
        out.append(dict(name=name, split="train", scene=os.path.join(SCENES, scene), path=path))
    for i in range(args.rooms):
        out.append(dict(name=f"room_{i:03d}", split="train", room=i))
    out.append(dict(name="test_sponza", split="test", scene=os.path.join(SCENES, "dabrovic_sponza/sponza.obj"),
                    path=os.path.join(ROOT, "data/paths/sponza_short.json")))
    out.append(dict(name="test_lamborghini", split="test", scene=os.path.join(SCENES, "lamborghini/lamborghini.obj"),
                    path="orbit:32"))
    out.append(dict(name="test_room_1000", split="test", room=1000))
    return out


def run(cmd):
    print("+", " ".join(cmd), flush=True)
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL)


def base_command(args, scene, path, frames, max_depth, clamp, flags, env):
    """`kestrel render-sequence` of a clip, without resolution, samples and outputs."""
    base = kestrel_mpi.prefix(args) + [args.kestrel, "render-sequence", scene, "--path", path, "--frames", str(frames),
                                       "--quiet", "--max-depth", str(max_depth), "--clamp", str(clamp)] + flags
    if env and env not in ("none", "default"):
        base += ["--env", env]
    return base


def render_denoised(args, base, d, f, w, h):
    """The inputs at 1/f of (w, h), 1 spp through kestrel's denoiser: what the real-time loop
    feeds the upsampler."""
    sub = os.path.join(d, f"x{f}_dn")
    run(base + ["--res", f"{w // f}x{h // f}", "--spp", "1", "--fixed-jitter", "--seed", "13",
                "--denoise", args.denoised, "-o", sub, "--pfm", os.path.join(sub, "pfm")])


def add_denoised(args, entry, d, w, h):
    """A finished clip rendered without --denoised: its denoised 1-spp inputs only, from the
    manifest entry's own scene, path and flags (the clean inputs and targets stay)."""
    base = base_command(args, entry["scene"], entry["path"], entry["frames"], entry["max_depth"], entry["clamp"],
                        entry["flags"], entry.get("env"))
    for f in (2, 4):
        render_denoised(args, base, d, f, w, h)
    entry["denoised"] = args.denoised


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", default=os.path.join(ROOT, "out", "upscale_dataset"))
    ap.add_argument("--kestrel", default=os.path.join(ROOT, "build", "release", "apps", "kestrel", "kestrel"))
    ap.add_argument("--split", default="all", choices=["train", "test", "all"])
    ap.add_argument("--res", default="320x180")
    ap.add_argument("--frames", type=int, default=12)
    ap.add_argument("--test-frames", type=int, default=16)
    ap.add_argument("--ref-spp", type=int, default=256)
    ap.add_argument("--test-ref-spp", type=int, default=384)
    ap.add_argument("--in-spp", type=int, default=128)
    ap.add_argument("--rooms", type=int, default=8)
    ap.add_argument("--max-depth", type=int, default=3, help="path vertices (fewer: less noise, what matters here is detail)")
    ap.add_argument("--clamp", type=float, default=8.0, help="sample radiance clamp (no fireflies in the targets)")
    ap.add_argument("--families", action="store_true", help="scene families (../denoise/families.py) instead of rooms and shared scenes")
    ap.add_argument("--seeds", type=int, default=6, help="--families: seeds per training family")
    ap.add_argument("--test-seeds", type=int, default=2, help="--families: seeds per held-out family")
    ap.add_argument("--no-movers", action="store_true",
                    help="--families: no moving objects in the training scenes (the static set the committed weights were trained on)")
    ap.add_argument("--denoised", default="", metavar="METHOD",
                    help="also x2_dn/, x4_dn/: the inputs at 1 spp denoised by METHOD (neural | svgf | atrous)")
    kestrel_mpi.add_arguments(ap)
    args = ap.parse_args()
    w, h = (int(v) for v in args.res.split("x"))
    if w % 4 or h % 4:
        sys.exit(f"--res {args.res}: width and height must be multiples of 4")
    os.makedirs(args.out, exist_ok=True)
    manifest_path = os.path.join(args.out, "manifest.json")
    manifest = json.load(open(manifest_path)) if os.path.exists(manifest_path) else {"clips": {}}
    order = [c for c in clips(args) if c["split"] == "test"] + [c for c in clips(args) if c["split"] == "train"]
    for clip in order:
        if args.split != "all" and clip["split"] != args.split:
            continue
        done = manifest["clips"].get(clip["name"])
        if done and args.denoised and not done.get("denoised"):
            add_denoised(args, done, os.path.join(args.out, clip["name"]), w, h)
            json.dump(manifest, open(manifest_path, "w"), indent=1)
        if done:
            continue
        d = os.path.join(args.out, clip["name"])
        t0 = time.time()
        scene, path, env, flags = clip.get("scene"), clip.get("path"), None, []
        if "family" in clip:
            info = families.make(clip["family"], clip["seed"], os.path.join(d, "scene"),
                                 movers=False if args.no_movers else clip.get("movers"))
            scene, path, flags = info["scene"], info["path"], info["flags"]
        elif "room" in clip:
            rd = os.path.join(d, "scene")
            run([sys.executable, os.path.join(HERE, "..", "denoise", "procedural.py"), str(clip["room"]), rd])
            scene, path = os.path.join(rd, "room.obj"), os.path.join(rd, "path.json")
            env = open(os.path.join(rd, "env.txt")).read().strip()
        test = clip["split"] == "test"
        frames = args.test_frames if test else args.frames
        base = base_command(args, scene, path, frames, args.max_depth, args.clamp, flags, env)
        for f in (2, 4):
            sub = os.path.join(d, f"x{f}")
            run(base + ["--res", f"{w // f}x{h // f}", "--spp", str(args.in_spp), "--fixed-jitter", "--seed", "11",
                        "-o", sub, "--pfm", os.path.join(sub, "pfm")])
            if args.denoised:
                render_denoised(args, base, d, f, w, h)
        ref_spp = args.test_ref_spp if test else args.ref_spp
        run(base + ["--res", args.res, "--spp", str(ref_spp), "--seed", "7", "-o", os.path.join(d, "full"), "--pfm",
                    os.path.join(d, "full", "pfm"), "--png", "1"])
        manifest.setdefault("commands", {})[clip["split"]] = "python3 scripts/upscale/make_dataset.py " + " ".join(sys.argv[1:])
        manifest["clips"][clip["name"]] = dict(split=clip["split"], scene=scene, path=path, env=env or "default",
                                               family=clip.get("family", ""), flags=flags,
                                               frames=frames, res=args.res, ref_spp=ref_spp, in_spp=args.in_spp,
                                               max_depth=args.max_depth, clamp=args.clamp, denoised=args.denoised,
                                               seconds=round(time.time() - t0, 1))
        json.dump(manifest, open(manifest_path, "w"), indent=1)
        print(f"{clip['name']}: {time.time() - t0:.0f} s", flush=True)


if __name__ == "__main__":
    main()
