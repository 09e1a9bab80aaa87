#!/usr/bin/env python3
"""Writes the fuzz harnesses' seed corpora (fuzz/corpus/NAME/): small valid inputs of every
format, so the fuzzers start from files that reach deep into each reader. Deterministic;
EXR, rays and hits files are made by the kestrel CLI.

    fuzz/make_corpus.py KESTREL_CLI
"""
import base64
import io
import json
import math
import os
import shutil
import struct
import subprocess
import sys
import tempfile
import zlib

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
K = os.path.abspath(sys.argv[1])
OUT = os.path.join(HERE, "corpus")


def put(name, file, data):
    d = os.path.join(OUT, name)
    os.makedirs(d, exist_ok=True)
    with open(os.path.join(d, file), "wb" if isinstance(data, bytes) else "w") as f:
        f.write(data)


def gltf_doc(animated, morph):
    pos = struct.pack("<9f", 0, 0, 0, 1, 0, 0, 0, 1, 0)
    nrm = struct.pack("<9f", 0, 0, 1, 0, 0, 1, 0, 0, 1)
    uv = struct.pack("<6f", 0, 0, 1, 0, 0, 1)
    idx = struct.pack("<3H", 0, 1, 2) + b"\0\0"
    times = struct.pack("<3f", 0, 0.5, 1)
    rots = struct.pack("<12f", 0, 0, 0, 1, 0, 0.7071, 0, 0.7071, 0, 1, 0, 0)
    dpos = struct.pack("<9f", 0, 0, 0.2, 0, 0, 0.2, 0, 0, 0.2)
    wts = struct.pack("<3f", 0, 1, 0)
    blob = pos + nrm + uv + idx + times + rots + dpos + wts
    offs = [0, 36, 72, 96, 104, 116, 164, 200]
    lens = [36, 36, 24, 6, 12, 48, 36, 12]
    views = [{"buffer": 0, "byteOffset": o, "byteLength": n} for o, n in zip(offs, lens)]
    acc = [
        {"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3", "min": [0, 0, 0], "max": [1, 1, 0]},
        {"bufferView": 1, "componentType": 5126, "count": 3, "type": "VEC3"},
        {"bufferView": 2, "componentType": 5126, "count": 3, "type": "VEC2"},
        {"bufferView": 3, "componentType": 5123, "count": 3, "type": "SCALAR"},
        {"bufferView": 4, "componentType": 5126, "count": 3, "type": "SCALAR", "min": [0], "max": [1]},
        {"bufferView": 5, "componentType": 5126, "count": 3, "type": "VEC4"},
        {"bufferView": 6, "componentType": 5126, "count": 3, "type": "VEC3"},
        {"bufferView": 7, "componentType": 5126, "count": 3, "type": "SCALAR"},
    ]
    prim = {"attributes": {"POSITION": 0, "NORMAL": 1, "TEXCOORD_0": 2}, "indices": 3, "material": 0}
    if morph:
        prim["targets"] = [{"POSITION": 6}]
    doc = {
        "asset": {"version": "2.0"},
        "buffers": [{"byteLength": len(blob), "uri": "data:application/octet-stream;base64," + base64.b64encode(blob).decode()}],
        "bufferViews": views, "accessors": acc,
        "materials": [{"pbrMetallicRoughness": {"baseColorFactor": [0.8, 0.2, 0.1, 1], "metallicFactor": 0.5,
                                                "roughnessFactor": 0.3}, "emissiveFactor": [0, 0, 0],
                       "extensions": {"KHR_materials_specular": {"specularFactor": 0.5,
                                                                 "specularColorFactor": [1, 0.5, 0.25]}}}],
        "meshes": [{"primitives": [prim], "weights": [0.0] if morph else []}],
        "nodes": [{"children": [1], "translation": [0, 1, 0]}, {"mesh": 0, "rotation": [0, 0, 0, 1], "scale": [1, 2, 1]}],
        "scenes": [{"nodes": [0]}], "scene": 0,
    }
    if animated:
        channels = [{"sampler": 0, "target": {"node": 1, "path": "rotation"}}]
        samplers = [{"input": 4, "output": 5, "interpolation": "LINEAR"}]
        if morph:
            channels.append({"sampler": 1, "target": {"node": 1, "path": "weights"}})
            samplers.append({"input": 4, "output": 7, "interpolation": "STEP"})
        doc["animations"] = [{"channels": channels, "samplers": samplers}]
    return doc, blob


def glb(doc, blob):
    doc = dict(doc)
    doc["buffers"] = [{"byteLength": len(blob)}]
    j = json.dumps(doc).encode()
    j += b" " * (-len(j) % 4)
    b = blob + b"\0" * (-len(blob) % 4)
    return (struct.pack("<III", 0x46546C67, 2, 12 + 8 + len(j) + 8 + len(b)) + struct.pack("<II", len(j), 0x4E4F534A) + j +
            struct.pack("<II", len(b), 0x004E4942) + b)


def png(w, h, rgba):
    def chunk(kind, data):
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)
    raw = b"".join(b"\0" + bytes(rgba[y * w * 4:(y + 1) * w * 4]) for y in range(h))
    return (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 6, 0, 0, 0)) +
            chunk(b"IDAT", zlib.compress(raw, 9)) + chunk(b"IEND", b""))


def main():
    shutil.rmtree(OUT, ignore_errors=True)
    # OBJ + MTL
    cornell = open(os.path.join(ROOT, "..", "shared", "scenes", "cornell_box", "cornell_box.obj")).read() \
        if os.path.exists(os.path.join(ROOT, "..", "shared", "scenes", "cornell_box", "cornell_box.obj")) else ""
    put("obj", "quad_mtl.obj", "mtllib fuzz.mtl\nusemtl red\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 1 1\n"
        "vn 0 0 1\nf 1/1/1 2/2/1 3/3/1 4/1/1\nusemtl light\nf -1 -2 -3\n#MTL\nnewmtl red\nKd 0.8 0.1 0.1\nKs 0.5 0.5 0.5\n"
        "Ns 100\nnewmtl light\nKe 5 5 5\nd 1\nillum 2\n")
    put("obj", "ngon.obj", "".join(f"v {math.cos(i):.4f} {math.sin(i):.4f} 0\n" for i in range(12)) +
        "f " + " ".join(str(i + 1) for i in range(12)) + "\ng part\ns 1\nf 1//1 2//1 3//1\n")
    if cornell:
        put("obj", "cornell.obj", cornell[:6000])
    # glTF / GLB
    for animated, morph, name in ((False, False, "static"), (True, False, "rotating"), (True, True, "morphing")):
        doc, blob = gltf_doc(animated, morph)
        put("gltf", f"{name}.gltf", json.dumps(doc, indent=1))
        put("glb", f"{name}.glb", glb(doc, blob))
    # PFM
    put("pfm", "rgb.pfm", b"PF\n3 2\n-1.0\n" + struct.pack("<18f", *[i / 17 for i in range(18)]))
    put("pfm", "gray_big_endian.pfm", b"Pf\n2 2\n1.0\n" + struct.pack(">4f", 0.1, 0.2, 0.3, 0.4))
    # images
    put("image", "tiny.png", png(4, 3, [(i * 37) % 256 for i in range(48)]))
    put("image", "tiny.hdr", b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y 2 +X 2\n" + bytes([128, 64, 32, 129] * 4))
    try:
        from PIL import Image  # Debian's python3-pil, where present, for a JPEG seed
        b = io.BytesIO()
        Image.new("RGB", (8, 8), (200, 100, 50)).save(b, "JPEG", quality=80)
        put("image", "tiny.jpg", b.getvalue())
    except ImportError:
        pass
    # EXR, rays and hits from the CLI
    with tempfile.TemporaryDirectory() as tmp:
        subprocess.run([K, "render", "builtin:cornell_box", "--res", "6x4", "--spp", "1", "-o", f"{tmp}/f.exr", "--quiet"],
                       check=True, capture_output=True)
        put("exr", "frame_all_aovs.exr", open(f"{tmp}/f.exr", "rb").read())
        subprocess.run([K, "rays", "builtin:cornell_box", "--res", "4x2", "--kind", "diffuse", "-o", f"{tmp}/r.rays"],
                       check=True, capture_output=True)
        subprocess.run([K, "trace", "builtin:cornell_box", "--rays", f"{tmp}/r.rays", "--hits", f"{tmp}/h.hits",
                        "--repeat", "1"], check=True, capture_output=True)
        put("rays", "diffuse.rays", open(f"{tmp}/r.rays", "rb").read())
        put("hits", "diffuse.hits", open(f"{tmp}/h.hits", "rb").read())
    # weights, camera paths, views, instances
    for w in ("denoiser.kdw", "upscaler.kdw"):
        put("weights", w, open(os.path.join(ROOT, "weights", w), "rb").read())
    for p in os.listdir(os.path.join(ROOT, "data", "paths")):
        put("camera_path", p, open(os.path.join(ROOT, "data", "paths", p)).read())
    put("camera_path", "lens.json", json.dumps({"keyframes": [
        {"time": 0, "eye": [0, 1, 5], "target": [0, 0, 0], "vfov": 40, "aperture": 0.1, "focus_distance": 5},
        {"time": 2.5, "eye": [3, 1, 4], "target": [0, 0.5, 0], "vfov": 60}]}))
    for v in os.listdir(os.path.join(ROOT, "data", "views")):
        put("views", v, open(os.path.join(ROOT, "data", "views", v)).read())
    put("instances", "grid.instances.txt", "# sx sy sz tx ty tz rot_y\n1 1 1 0 0 0 0\n2 2 2 3 0 0 45\n"
        "0.5 0.5 0.5 -3 1 2 -90\n")
    print("corpora:", {d: len(os.listdir(os.path.join(OUT, d))) for d in sorted(os.listdir(OUT))})


if __name__ == "__main__":
    main()
