#!/usr/bin/env python3
"""The denoiser's dataset, rendered by `kestrel render-sequence`: per clip a 1-spp input
sequence (also 2 and 4 spp for the test clips) with every AOV as PFMs, and a reference
of the same frames at --ref-spp (another seed). Clips: shared scenes (turntables and
paths) and procedural rooms (procedural.py). The test clips' scenes are never used in
training: Sponza, the Lamborghini and procedural rooms with seeds >= 1000.

    make_dataset.py [--out out/denoise_dataset] [--split train|test|all] [--ref-spp 256]
                    [--test-ref-spp 1024] [--res 256x144] [--frames 6] [--rooms 10]

With --families (the dataset of architectures 3 and 4): the training clips are the TRAIN families
of families.py (--seeds each) and their targets independent noisy renders (Noise2Noise, at
--ref-spp); the test clips are the HELDOUT families (--test-seeds each, never seen in
training) and the shared Sponza and Lamborghini, with --test-frames frames and references at
--test-ref-spp:

    make_dataset.py --families --out out/denoise_families --frames 8 --ref-spp 64 \
                    --test-frames 16 --test-ref-spp 256 --test-movers 1

Half of the training scenes have moving objects (families.add_movers); the held-out ones are
static, and --test-movers N adds N clips per held-out family with moving objects
(test_<family>_moving_<seed>). --no-movers makes the static training set the committed
weights were trained on (the default before 2026-12-05, night).

Re-running skips finished clips (a clip is finished when its manifest entry exists).
"""
import argparse
import json
import os
import subprocess
import sys
import time

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))
import kestrel_mpi  # noqa: E402

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import families  # noqa: E402

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.normpath(os.path.join(HERE, "..", ".."))
SCENES = os.path.normpath(os.path.join(ROOT, "..", "shared", "scenes"))


def family_clips(args):
    """--families: TRAIN families x --seeds for training (Noise2Noise targets), HELDOUT
    families x --test-seeds and the shared Sponza and Lamborghini for evaluation."""
    return families.dataset_clips(args.seeds, args.test_seeds, test_movers=args.test_movers, shared=[
        dict(name="test_sponza", scene=os.path.join(SCENES, "dabrovic_sponza/sponza.obj"),
             path=os.path.join(ROOT, "data/paths/sponza_short.json"), env=None),
        dict(name="test_lamborghini", scene=os.path.join(SCENES, "lamborghini/lamborghini.obj"), path="orbit:24",
             env=None)])


def clips(args):
    if args.families:
        return family_clips(args)
    out = []
    train_shared = [
        ("cornell_box", "cornell_box/cornell_box.obj", "orbit:16", None),
        ("teapot", "teapot/teapot.obj", "orbit:30", None),
        ("bunny", "stanford_bunny/stanford_bunny.obj", "orbit:30", None),
        ("gltf_cornell_box", "gltf_cornell_box/cornell_box.gltf", "orbit:16", None),
        ("box_animated", "gltf_box_animated/BoxAnimated.gltf", os.path.join(ROOT, "data/paths/box_animated_orbit.json"), None),
        ("flight_helmet", "gltf_flight_helmet/FlightHelmet.gltf", "orbit:30", None),
    ]
    for name, scene, path, env in train_shared:
        out.append(dict(name=name, split="train", scene=os.path.join(SCENES, scene), path=path, env=env))
    for i in range(args.rooms):
        out.append(dict(name=f"room_{i:03d}", split="train", room=i))
    out.append(dict(name="test_sponza", split="test", scene=os.path.join(SCENES, "dabrovic_sponza/sponza.obj"),
                    path=os.path.join(ROOT, "data/paths/sponza_short.json"), env=None))
    out.append(dict(name="test_lamborghini", split="test", scene=os.path.join(SCENES, "lamborghini/lamborghini.obj"),
                    path="orbit:24", env=None))
    out.append(dict(name="test_room_1000", split="test", room=1000))
    return out


def run(cmd):
    print("+", " ".join(cmd), flush=True)
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", default=os.path.join(ROOT, "out", "denoise_dataset"))
    ap.add_argument("--kestrel", default=os.path.join(ROOT, "build", "release", "apps", "kestrel", "kestrel"))
    ap.add_argument("--split", default="all", choices=["train", "test", "all"])
    ap.add_argument("--ref-spp", type=int, default=256)
    ap.add_argument("--test-ref-spp", type=int, default=1024)
    ap.add_argument("--res", default="256x144")
    ap.add_argument("--frames", type=int, default=6)
    ap.add_argument("--test-frames", type=int, default=8)
    ap.add_argument("--rooms", type=int, default=10)
    ap.add_argument("--families", action="store_true", help="scene families (families.py) instead of rooms and shared scenes")
    ap.add_argument("--seeds", type=int, default=8, help="--families: seeds per training family")
    ap.add_argument("--test-seeds", type=int, default=3, help="--families: seeds per held-out family")
    ap.add_argument("--test-movers", type=int, default=0,
                    help="--families: seeds per held-out family with moving objects (clips test_<family>_moving_<seed>)")
    ap.add_argument("--no-movers", action="store_true",
                    help="--families: no moving objects in the training scenes (the static set the committed weights were trained on)")
    kestrel_mpi.add_arguments(ap)
    args = ap.parse_args()
    os.makedirs(args.out, exist_ok=True)
    manifest_path = os.path.join(args.out, "manifest.json")
    manifest = json.load(open(manifest_path)) if os.path.exists(manifest_path) else {"clips": {}}
    for clip in clips(args):
        if args.split != "all" and clip["split"] != args.split:
            continue
        if clip["name"] in manifest["clips"]:
            continue
        d = os.path.join(args.out, clip["name"])
        t0 = time.time()
        scene, path, env = clip.get("scene"), clip.get("path"), clip.get("env")
        flags = []
        if "family" in clip:
            info = families.make(clip["family"], clip["seed"], os.path.join(d, "scene"),
                                 movers=False if args.no_movers and not clip.get("movers") else clip.get("movers"))
            scene, path, flags = info["scene"], info["path"], info["flags"]
        elif "room" in clip:
            rd = os.path.join(d, "scene")
            run([sys.executable, os.path.join(HERE, "procedural.py"), str(clip["room"]), rd])
            scene, path = os.path.join(rd, "room.obj"), os.path.join(rd, "path.json")
            env = open(os.path.join(rd, "env.txt")).read().strip()
        test = clip["split"] == "test"
        frames = args.test_frames if test else args.frames
        base = kestrel_mpi.prefix(args) + [args.kestrel, "render-sequence", scene, "--path", path, "--frames", str(frames), "--res", args.res,
                "--quiet"] + flags
        if env and env != "none":
            base += ["--env", env]
        for spp in ([1, 2, 4] if test else [1]):
            run(base + ["--spp", str(spp), "--seed", str(100 + spp), "-o", os.path.join(d, f"spp{spp}"),
                        "--pfm", os.path.join(d, f"spp{spp}", "pfm")])
        ref_spp = args.test_ref_spp if test else args.ref_spp
        run(base + ["--spp", str(ref_spp), "--seed", "7", "-o", os.path.join(d, "ref"), "--pfm",
                    os.path.join(d, "ref", "pfm"), "--png", "1"])
        command = "python3 scripts/denoise/make_dataset.py " + " ".join(sys.argv[1:])
        manifest.setdefault("commands", {})[clip["split"]] = command
        manifest.setdefault("targets", {})[clip["split"]] = (
            f"an independent {ref_spp}-spp render (seed 7) of each frame (Noise2Noise)" if not test
            else f"{ref_spp}-spp references")
        manifest["clips"][clip["name"]] = dict(split=clip["split"], scene=scene, path=path, env=env or "default",
                                               family=clip.get("family", ""), flags=flags,
                                               frames=frames, res=args.res, ref_spp=ref_spp,
                                               seconds=round(time.time() - t0, 1))
        json.dump(manifest, open(manifest_path, "w"), indent=1)
        print(f"{clip['name']}: {time.time() - t0:.0f} s", flush=True)


if __name__ == "__main__":
    main()
