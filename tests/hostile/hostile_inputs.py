#!/usr/bin/env python3
"""Hostile inputs against the kestrel CLI, as a user with bad files would feed them.

Every case runs the CLI under a 2 GiB address-space limit and a time limit and must end with a
non-zero exit (not a signal, not a time-out), a message on stderr naming the file (or flag),
no `std::` text, and any existing output file unchanged. Cases that must succeed say so.

    hostile_inputs.py KESTREL_CLI WORK_DIR
"""
import json
import os
import resource
import shutil
import signal
import stat
import struct
import subprocess
import sys
import zlib

K, WORK = os.path.abspath(sys.argv[1]), os.path.abspath(sys.argv[2])
LIMIT = 2 << 30
failures = []
passed = 0


def limits():
    if not os.environ.get("KESTREL_SANITIZED"):  # ASan's shadow memory needs terabytes of address space
        resource.setrlimit(resource.RLIMIT_AS, (LIMIT, LIMIT))


def run(args, timeout=60, preexec=limits):
    try:
        r = subprocess.run([K, *map(str, args)], capture_output=True, text=True, timeout=timeout, preexec_fn=preexec,
                           cwd=WORK)
        return r.returncode, r.stdout + r.stderr
    except subprocess.TimeoutExpired:
        return "timeout", ""


def expect_error(name, args, needles, keep=(), timeout=60, preexec=limits):
    global passed
    before = {p: open(p, "rb").read() for p in keep}
    code, out = run(args, timeout, preexec)
    problems = []
    if code == "timeout":
        problems.append(f"hung (no exit within {timeout} s)")
    elif code == 0:
        problems.append("exit 0")
    elif code < 0 or code >= 128:
        problems.append(f"died with signal/exit {code}")
    for n in needles:
        if n not in out:
            problems.append(f"message lacks {n!r}")
    if "std::" in out or "basic_filebuf" in out:
        problems.append("std:: text reached the user")
    if "internal error" in out:
        problems.append("an internal error instead of one naming the problem")
    for p, data in before.items():
        if not os.path.exists(p) or open(p, "rb").read() != data:
            problems.append(f"{p} was damaged")
    leftovers = [f for f in os.listdir(WORK) if ".partial-" in f]
    if leftovers:
        problems.append(f"left temporaries {leftovers}")
    if problems:
        failures.append(f"{name}: {'; '.join(problems)}\n    {' '.join(map(str, args))}\n    output: {out.strip()[:400]}")
    else:
        passed += 1


def expect_ok(name, args, needles=()):
    global passed
    code, out = run(args)
    missing = [n for n in needles if n not in out]
    if code != 0 or missing:
        failures.append(f"{name}: exit {code}, missing {missing}\n    output: {out.strip()[:400]}")
    else:
        passed += 1


def write(name, data):
    path = os.path.join(WORK, name)
    with open(path, "wb" if isinstance(data, bytes) else "w") as f:
        f.write(data)
    return path


def gltf_with(accessors, buffer_views, buffer_bytes, extra=None, name="bad.gltf"):
    import base64
    doc = {
        "asset": {"version": "2.0"},
        "buffers": [{"byteLength": len(buffer_bytes),
                     "uri": "data:application/octet-stream;base64," + base64.b64encode(buffer_bytes).decode()}],
        "bufferViews": buffer_views, "accessors": accessors,
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0}}]}],
        "nodes": [{"mesh": 0}], "scenes": [{"nodes": [0]}], "scene": 0,
    }
    doc.update(extra or {})
    return write(name, json.dumps(doc))


def png_chunk(kind, data):
    return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)


def main():
    global passed
    shutil.rmtree(WORK, ignore_errors=True)
    os.makedirs(WORK)
    tri = struct.pack("<9f", 0, 0, 0, 1, 0, 0, 0, 1, 0)

    # --- glTF: overflowing accessors and samplers, offsets near 2^64, DAG node graphs.
    views = [{"buffer": 0, "byteOffset": 0, "byteLength": len(tri)}]
    ok_acc = {"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3"}
    anim = {"animations": [{"channels": [{"sampler": 0, "target": {"node": 0, "path": "rotation"}}],
                            "samplers": [{"input": 1, "output": 2}]}]}
    path = gltf_with([ok_acc, {"bufferView": 0, "componentType": 5126, "count": 2, "type": "SCALAR"},
                      {"bufferView": 0, "componentType": 5126, "count": 4611686018427387904, "type": "VEC4"}],
                     views, tri, anim, "sampler_overflow.gltf")
    expect_error("glTF sampler count x components overflow", ["render-sequence", path, "--path", "orbit", "--frames", 1,
                                                              "--res", "8x8", "-o", "seq_out", "--quiet"],
                 ["sampler_overflow.gltf", "reads past the end"])
    path = gltf_with([dict(ok_acc, byteOffset=18446744073709551600)], views, tri, None, "offset_wrap.gltf")
    expect_error("glTF accessor byteOffset near 2^64", ["bvh", path], ["offset_wrap.gltf"])
    path = gltf_with([dict(ok_acc, count=6148914691236517206)], views, tri, None, "count_wrap.gltf")
    expect_error("glTF accessor count x stride wraps", ["bvh", path], ["count_wrap.gltf", "reads past the end"])
    nodes = [{"children": [i + 1, i + 1]} if i < 40 else {"mesh": 0} for i in range(41)]
    path = gltf_with([ok_acc], views, tri, {"nodes": nodes}, "dag.gltf")
    expect_error("glTF nodes sharing children (DAG)", ["bvh", path], ["dag.gltf", "tree"], timeout=20)
    nodes = [{"children": [1]}, {"children": [0], "mesh": 0}]
    path = gltf_with([ok_acc], views, tri, {"nodes": nodes}, "cycle.gltf")
    expect_error("glTF node cycle", ["bvh", path], ["cycle.gltf"])
    extra = {"extensionsUsed": ["KHR_draco_mesh_compression"],
             "extensionsRequired": ["KHR_draco_mesh_compression"]}
    path = gltf_with([ok_acc], views, tri, extra, "draco.gltf")
    expect_error("glTF requiring an extension kestrel does not read", ["render", path, "-o",
                 os.path.join(os.path.dirname(path), "draco.exr")],
                 ["draco.gltf", "KHR_draco_mesh_compression"])

    for label, glass in (("negative index of refraction", {"KHR_materials_ior": {"ior": -2}}),
                         ("zero attenuation distance",
                          {"KHR_materials_volume": {"thicknessFactor": 1, "attenuationDistance": 0}})):
        extra = {"materials": [{"name": "crystal", "extensions": glass}],
                 "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "material": 0}]}]}
        path = gltf_with([ok_acc], views, tri, extra, "glassy.gltf")
        expect_error("glTF glass with a " + label, ["render", path, "--res", "8x8", "-o",
                     os.path.join(os.path.dirname(path), "glassy.exr")], ["glassy.gltf", "crystal"])

    extra = {"skins": [{"joints": [99]}], "nodes": [{"mesh": 0, "skin": 0}]}
    path = gltf_with([ok_acc], views, tri, extra, "skin.gltf")
    expect_error("glTF skin naming a missing joint", ["render", path, "--res", "8x8", "-o",
                 os.path.join(os.path.dirname(path), "skin.exr")], ["skin.gltf", "joint"])
    int_acc = dict(ok_acc, componentType=5125)  # UNSIGNED_INT positions: no glTF allows them
    path = gltf_with([int_acc], views, tri, None, "int_positions.gltf")
    expect_error("glTF positions as 32-bit integers", ["bvh", path], ["int_positions.gltf", "component type"])

    # --- Images whose headers claim far more than the file holds.
    path = write("huge.pfm", b"PF\n16000 16000\n-1.0\n" + b"\0" * 64)
    expect_error("84-byte PFM claiming 16k x 16k", ["render", "builtin:cornell_box", "--env", path, "--res", "8x8",
                                                    "--png", "x.png", "--quiet"], ["huge.pfm", "truncated"])
    raw = b"".join(b"\0" + b"\0" * (30000 * 3) for _ in range(4))
    png = (b"\x89PNG\r\n\x1a\n" + png_chunk(b"IHDR", struct.pack(">IIBBBBB", 30000, 30000, 8, 2, 0, 0, 0)) +
           png_chunk(b"IDAT", zlib.compress(raw, 9)) + png_chunk(b"IEND", b""))
    path = write("huge.png", png)
    expect_error("small PNG environment claiming 30000 x 30000", ["render", "builtin:cornell_box", "--env", path, "--res",
                                                                  "8x8", "--png", "x.png", "--quiet"], ["huge.png"])
    # An EXR made by kestrel, its data window then widened in place.
    expect_ok("write a small EXR", ["render", "builtin:cornell_box", "--res", "8x8", "-o", "small.exr", "--quiet"])
    data = bytearray(open(os.path.join(WORK, "small.exr"), "rb").read())
    at = data.find(b"dataWindow\0box2i\0")
    if at < 0:
        failures.append("could not find the EXR data window to patch")
    else:
        at += len(b"dataWindow\0box2i\0") + 4
        data[at:at + 16] = struct.pack("<4i", 0, 0, 29999, 29999)
        path = write("window.exr", bytes(data))
        expect_error("EXR with a 30000 x 30000 data window", ["render", "builtin:cornell_box", "--env", path, "--res",
                                                              "8x8", "--png", "x.png", "--quiet"], ["window.exr"])

    # --- Devices, FIFOs and folders where files are expected: no hang, no endless read.
    fifo = os.path.join(WORK, "fifo")
    os.mkfifo(fifo)
    os.mkdir(os.path.join(WORK, "folder.mtl"))
    for target, label in (("/dev/zero", "a character device"), (fifo, "a FIFO"), ("folder.mtl", "a folder")):
        obj = write(f"mtl_{os.path.basename(target)}.obj", f"mtllib {target}\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
        expect_error(f"mtllib naming {label}", ["bvh", obj], [label], timeout=20)
        expect_error(f"--weights naming {label}", ["denoise", "--hdr", "x.pfm", "-o", "y.pfm", "--weights", target],
                     [label, os.path.basename(target)], timeout=20)
    doc = {"asset": {"version": "2.0"}, "buffers": [{"byteLength": 36, "uri": "fifo"}],
           "bufferViews": views, "accessors": [ok_acc], "meshes": [{"primitives": [{"attributes": {"POSITION": 0}}]}],
           "nodes": [{"mesh": 0}], "scenes": [{"nodes": [0]}]}
    path = write("fifo_buffer.gltf", json.dumps(doc))
    expect_error("glTF buffer URI naming a FIFO", ["bvh", path], ["fifo"], timeout=20)
    expect_error("scene naming a folder", ["bvh", WORK + "/folder.mtl"], ["folder.mtl"])

    # --- Outputs: devices refused, full disks reported, existing files never damaged.
    expect_ok("an old output", ["render", "builtin:cornell_box", "--res", "8x8", "-o", "old.exr", "--quiet"])
    old = os.path.join(WORK, "old.exr")
    # A .png name that is a device (a link to /dev/full): refused as a device, not written.
    full_png = os.path.join(WORK, "full.png")
    if not os.path.lexists(full_png):
        os.symlink("/dev/full", full_png)
    expect_error("PNG to /dev/full", ["render", "builtin:cornell_box", "--res", "8x8", "--png", "full.png", "--quiet"],
                 ["full.png", "character device"])
    # Outputs named for another format: an error, not an EXR in a .png or a PNG in a .exr.
    expect_error("-o x.png", ["render", "builtin:cornell_box", "--res", "8x8", "-o", "x.png", "--quiet"],
                 ["x.png", ".exr"])
    expect_error("--png x.exr", ["render", "builtin:cornell_box", "--res", "8x8", "--png", "x.exr", "--quiet"],
                 ["x.exr", ".png"])
    expect_error("preview -o x.exr", ["preview", "builtin:cornell_box", "--res", "8x8", "-o", "x.exr"], ["x.exr", ".png"])
    expect_error("--exposure inf", ["render", "builtin:cornell_box", "--res", "8x8", "--png", "x.png", "--exposure",
                                    "inf", "--quiet"], ["--exposure"])
    expect_ok("rays to trace", ["rays", "builtin:cornell_box", "--res", "8x8", "-o", "r.rays"])
    expect_error(".hits to /dev/full", ["trace", "builtin:cornell_box", "--rays", "r.rays", "--hits", "/dev/full"],
                 ["/dev/full"])
    expect_error("-o old.exr with --png into a missing folder", ["render", "builtin:cornell_box", "--res", "8x8", "-o",
                                                                 "old.exr", "--png", "missing_dir/x.png", "--quiet"],
                 ["missing_dir"], keep=[old])

    # A file where an output folder is to be made: an error naming it, before any work.
    write("a_file", b"not a folder")
    for name, args in (("-o", ["render", "builtin:cornell_box", "--res", "8x8", "-o", "a_file/x.exr"]),
                       ("--pfm", ["render", "builtin:cornell_box", "--res", "8x8", "--pfm", "a_file/pfm"]),
                       ("render-sequence -o", ["render-sequence", "builtin:cornell_box", "--path", "orbit:1",
                                               "--frames", "1", "--res", "8x8", "-o", "a_file/seq"]),
                       ("run -o", ["run", "builtin:cornell_box", "--frames", "1", "-o", "a_file/run"]),
                       ("denoise -o", ["denoise", "-i", "old.exr", "-o", "a_file/d.exr"])):
        expect_error(f"{name} below a file", args + ["--quiet"], ["a_file", "cannot create the folder"])

    def small_disk():  # writes past 64 KiB fail (EFBIG) as on a full disk; the signal is ignored
        limits()
        resource.setrlimit(resource.RLIMIT_FSIZE, (65536, 65536))
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)

    expect_error("EXR cut short by a full disk", ["render", "builtin:cornell_box", "--res", "160x120", "-o", "old.exr",
                                                  "--quiet"], ["old.exr"], keep=[old], preexec=small_disk)
    os.makedirs(os.path.join(WORK, "pfm_old"), exist_ok=True)
    pfm_old = write("pfm_old/color.pfm", b"the old colour")
    expect_error("PFM cut short by a full disk", ["render", "builtin:cornell_box", "--res", "160x120", "--pfm", "pfm_old",
                                                  "--quiet"], ["pfm_old"], keep=[pfm_old], preexec=small_disk)
    expect_error("rays file cut short by a full disk", ["rays", "builtin:cornell_box", "--res", "200x200", "-o", "r.rays"],
                 ["r.rays"], keep=[os.path.join(WORK, "r.rays")], preexec=small_disk)

    # --- OBJ limits: long faces, huge indices, NaN vertices, MTL garbage.
    ring = "".join(f"v {1 + 0.5 * __import__('math').cos(i / 300 * 6.283):.6f} "
                   f"{0.5 * __import__('math').sin(i / 300 * 6.283):.6f} 0\n" for i in range(300))
    path = write("long_face.obj", ring + "f " + " ".join(str(i + 1) for i in range(300)) + "\n")
    code, out = run(["bvh", path, "--json"])
    try:
        got = json.loads(next(line for line in out.splitlines() if line.startswith("{"))) if code == 0 else {}
    except (ValueError, StopIteration):
        got = {}
    if got.get("triangles") != 298:
        failures.append(f"300-corner face: expected 298 triangles, got {got.get('triangles')} (exit {code}) {out[:200]}")
    else:
        passed += 1
    path = write("big_index.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nv 2 2 0\nf 1 2 4294967300\n")
    expect_error("face index 2^32 + 4", ["bvh", path], ["big_index.obj:6", "out of range"])
    path = write("nan.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nv nan 1 0\nf 1 2 3\nf 2 3 4\n")
    expect_ok("NaN vertices render with a warning", ["render", path, "--res", "8x8", "--png", "nan.png", "--quiet"],
              ["warning", "1 of 2 triangles skipped", "NaN"])
    # Finite coordinates near the float limit (areas and doubled centroids overflow): the
    # default builder used to recurse until the stack ran out.
    far = "".join(f"v 0 0 {i}\nv 1 0 {i}\nv 0 1 {i}\nv -3e38 -3e38 {i}e36\nv 3e38 -3e38 {i + 1}e36\n"
                  f"v 3e38 3.3e38 3e38\n" for i in range(300))
    far += "".join(f"f {6 * i + 1} {6 * i + 2} {6 * i + 3}\nf {6 * i + 4} {6 * i + 5} {6 * i + 6}\n" for i in range(300))
    path = write("far.obj", far)
    expect_error("coordinates near 3.4e38 render", ["render", path, "--res", "16x16", "--png", "far.png", "--quiet"],
                 ["too large to frame", "--view"])
    for quality in ("balanced", "fast", "high"):
        expect_ok(f"coordinates near 3.4e38, quality {quality}",
                  ["bvh", path, "--quality", quality, "--repeat", 1, "--json"], ['"valid": true'])
    write("garbage.mtl", "newmtl m\nKd abc 0.5 0.5\n")
    path = write("garbage.obj", "mtllib garbage.mtl\nusemtl m\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    expect_error("MTL 'Kd abc'", ["bvh", path], ["garbage.mtl:2", "Kd"])

    # --- Messages and strict flags.
    path = write("far_path.json", json.dumps({"keyframes": [
        {"time": 0, "eye": [0, 0, 5], "target": [0, 0, 0]}, {"time": 1e300, "eye": [0, 0, 6], "target": [0, 0, 0]}]}))
    expect_error("camera path with a huge time", ["render-sequence", "builtin:cornell_box", "--path", path, "--frames", 2,
                                                  "--res", "8x8", "-o", "seq", "--quiet"], ["far_path.json", "keyframe 1"])
    expect_error("--res 16x16junk", ["render", "builtin:cornell_box", "--res", "16x16junk", "--png", "x.png"], ["16x16junk"])
    expect_error("--threads -5", ["render", "builtin:cornell_box", "--threads", "-5", "--png", "x.png"], ["--threads"])
    json_part = json.dumps({"asset": {"version": "2.0"}, "buffers": [{"byteLength": 36}],
                            "bufferViews": views, "accessors": [ok_acc],
                            "meshes": [{"primitives": [{"attributes": {"POSITION": 0}}]}],
                            "nodes": [{"mesh": 0}], "scenes": [{"nodes": [0]}]}).encode()
    json_part += b" " * (-len(json_part) % 4)
    glb = (struct.pack("<III", 0x46546C67, 2, 12 + 8 + len(json_part) + 8 + len(tri)) +
           struct.pack("<II", len(json_part), 0x4E4F534A) + json_part + struct.pack("<II", len(tri), 0x004E4942) + tri)
    path = write("UPPER.GLB", glb)
    expect_ok("a valid .GLB with an upper-case extension", ["bvh", path], ["1 triangles: 1 valid"])

    # --- Lights: bad glTF punctual lights and bad --sun flags.
    for kind, light, needle in [("unknown type", {"name": "odd", "type": "area"}, "unknown type"),
                                ("negative intensity", {"name": "neg", "type": "point", "intensity": -3}, "negative"),
                                ("inverted cone", {"name": "cone", "type": "spot",
                                                   "spot": {"innerConeAngle": 1.2, "outerConeAngle": 0.3}}, "cone")]:
        extra = {"extensionsUsed": ["KHR_lights_punctual"],
                 "extensions": {"KHR_lights_punctual": {"lights": [light]}},
                 "nodes": [{"mesh": 0}, {"extensions": {"KHR_lights_punctual": {"light": 0}}}],
                 "scenes": [{"nodes": [0, 1]}]}
        path = gltf_with([ok_acc], views, tri, extra, "bad_light.gltf")
        expect_error(f"glTF light: {kind}", ["render", path, "--res", "8x8", "--png", "x.png", "--quiet"],
                     ["bad_light.gltf", light["name"], needle])
    extra = {"nodes": [{"mesh": 0}, {"extensions": {"KHR_lights_punctual": {"light": 5}}}], "scenes": [{"nodes": [0, 1]}]}
    path = gltf_with([ok_acc], views, tri, extra, "missing_light.gltf")
    expect_error("glTF node names a missing light", ["render", path, "--res", "8x8", "--png", "x.png", "--quiet"],
                 ["missing_light.gltf", "missing light 5"])
    for sun in ["0,95", "nan,10", "10", "0,10,-2"]:
        expect_error(f"--sun {sun}", ["render", "builtin:cornell_box", "--sun", sun, "--res", "8x8", "--png", "x.png"],
                     ["--sun", sun])
    expect_error("--sky with --env", ["run", "builtin:cornell_box", "--sky", "--env", "sky", "--frames", 1, "-o", "run_out"],
                 ["--sky"])

    print(f"{passed} passed, {len(failures)} failed")
    for f in failures:
        print("FAIL", f)
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
