#!/usr/bin/env python3
"""Procedural rooms for the denoiser's dataset: a box room (closed with ceiling lights, or
open to the sky through a window), random boxes, spheres and cylinders with random
materials (diffuse, textured, glossy coat, rough and polished metal), and a short camera
walk inside. Everything follows from the seed.

    procedural.py SEED OUT_DIR   ->  OUT_DIR/room.obj, room.mtl, tex_*.png, path.json, env.txt
"""
import json
import math
import os
import random
import sys

from PIL import Image, ImageDraw


def texture(rng, path):
    n = 256
    img = Image.new("RGB", (n, n))
    d = ImageDraw.Draw(img)
    a = tuple(rng.randint(20, 240) for _ in range(3))
    b = tuple(rng.randint(20, 240) for _ in range(3))
    kind = rng.choice(["checker", "stripes", "dots", "bricks"])
    d.rectangle([0, 0, n, n], fill=a)
    k = rng.choice([4, 8, 16, 32])
    s = n // k
    if kind == "checker":
        for y in range(k):
            for x in range(k):
                if (x + y) % 2:
                    d.rectangle([x * s, y * s, x * s + s - 1, y * s + s - 1], fill=b)
    elif kind == "stripes":
        for x in range(0, k, 2):
            d.rectangle([x * s, 0, x * s + s - 1, n], fill=b)
    elif kind == "dots":
        for y in range(k):
            for x in range(k):
                d.ellipse([x * s + s // 4, y * s + s // 4, x * s + 3 * s // 4, y * s + 3 * s // 4], fill=b)
    else:
        for y in range(k):
            off = (s // 2) if y % 2 else 0
            for x in range(-1, k):
                d.rectangle([x * s + off + 1, y * s + 1, x * s + off + s - 2, y * s + s // 2 - 2], fill=b)
    img.save(path)


class Mesh:
    def __init__(self):
        self.v, self.vt, self.groups = [], [], []  # groups: (material, faces[(vi, ti) x3])
        self.solids = []  # bounding boxes (lo, hi) of the boxes, spheres and cylinders

    def quad(self, mat, p0, p1, p2, p3, uv_scale=1.0):
        base, tbase = len(self.v), len(self.vt)
        self.v += [p0, p1, p2, p3]
        self.vt += [(0, 0), (uv_scale, 0), (uv_scale, uv_scale), (0, uv_scale)]
        self.groups.append((mat, [[(base + 0, tbase + 0), (base + 1, tbase + 1), (base + 2, tbase + 2)],
                                  [(base + 0, tbase + 0), (base + 2, tbase + 2), (base + 3, tbase + 3)]]))

    def box(self, mat, c, h, yaw, uv_scale=1.0):
        cs, sn = math.cos(yaw), math.sin(yaw)

        def p(x, y, z):
            x, z = x * h[0], z * h[2]
            return (c[0] + cs * x - sn * z, c[1] + y * h[1], c[2] + sn * x + cs * z)
        f = [((-1, -1, 1), (1, -1, 1), (1, 1, 1), (-1, 1, 1)), ((1, -1, -1), (-1, -1, -1), (-1, 1, -1), (1, 1, -1)),
             ((1, -1, 1), (1, -1, -1), (1, 1, -1), (1, 1, 1)), ((-1, -1, -1), (-1, -1, 1), (-1, 1, 1), (-1, 1, -1)),
             ((-1, 1, 1), (1, 1, 1), (1, 1, -1), (-1, 1, -1)), ((-1, -1, -1), (1, -1, -1), (1, -1, 1), (-1, -1, 1))]
        for q in f:
            self.quad(mat, *[p(*v) for v in q], uv_scale=uv_scale)
        corners = [p(x, y, z) for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)]
        self.solids.append((tuple(min(q[i] for q in corners) for i in range(3)),
                            tuple(max(q[i] for q in corners) for i in range(3))))

    def room_shell(self, floor, side, back, ceiling, W, H, D, window=None):
        """An inward-facing box [0, W] x [0, H] x [0, D]: floor, ceiling, side walls (x = 0, W),
        back walls (z = 0, D); window = (x0, x1, y0, y1) is a hole in the z = D wall (built from
        the four quads around it)."""
        self.quad(floor, (0, 0, 0), (W, 0, 0), (W, 0, D), (0, 0, D), uv_scale=W / 2)
        self.quad(ceiling, (0, H, D), (W, H, D), (W, H, 0), (0, H, 0), uv_scale=W / 2)
        self.quad(side, (0, 0, 0), (0, 0, D), (0, H, D), (0, H, 0), uv_scale=D / 2)
        self.quad(side, (W, 0, D), (W, 0, 0), (W, H, 0), (W, H, D), uv_scale=D / 2)
        self.quad(back, (W, 0, 0), (0, 0, 0), (0, H, 0), (W, H, 0), uv_scale=W / 2)
        if window:
            x0, x1, y0, y1 = window
            for (a0, a1, b0, b1) in [(0, x0, 0, H), (x1, W, 0, H), (x0, x1, 0, y0), (x0, x1, y1, H)]:
                self.quad(back, (a0, b0, D), (a1, b0, D), (a1, b1, D), (a0, b1, D), uv_scale=1)
        else:
            self.quad(back, (0, 0, D), (W, 0, D), (W, H, D), (0, H, D), uv_scale=W / 2)

    def surface(self, mat, c, r, kind, seg=24, height=1.0):
        rows, cols = seg // 2, seg
        y0, y1 = (c[1] - r, c[1] + r) if kind == "sphere" else (c[1], c[1] + height)
        self.solids.append(((c[0] - r, y0, c[2] - r), (c[0] + r, y1, c[2] + r)))
        base, tbase = len(self.v), len(self.vt)
        for i in range(rows + 1):
            t = i / rows
            for j in range(cols + 1):
                u = j / cols
                ph = 2 * math.pi * u
                if kind == "sphere":
                    th = math.pi * t
                    pt = (c[0] + r * math.sin(th) * math.cos(ph), c[1] + r * math.cos(th), c[2] + r * math.sin(th) * math.sin(ph))
                else:
                    pt = (c[0] + r * math.cos(ph), c[1] + height * (1 - t), c[2] + r * math.sin(ph))
                self.v.append(pt)
                self.vt.append((u * 4, t * 2))
        faces = []
        for i in range(rows):
            for j in range(cols):
                a = (i * (cols + 1) + j)
                b, cc, d = a + 1, a + cols + 1, a + cols + 2
                # A sphere's first and last rows meet at the poles: one triangle of each quad
                # there has zero area and is left out.
                if not (kind == "sphere" and i == 0):
                    faces.append([(base + a, tbase + a), (base + cc, tbase + cc), (base + b, tbase + b)])
                if not (kind == "sphere" and i == rows - 1):
                    faces.append([(base + b, tbase + b), (base + cc, tbase + cc), (base + d, tbase + d)])
        self.groups.append((mat, faces))


def material(rng, name, tex_dir, textures):
    kind = rng.choices(["diffuse", "textured", "glossy", "metal"], [4, 3, 2, 1])[0]
    col = [round(rng.uniform(0.05, 0.9), 3) for _ in range(3)]
    lines = [f"newmtl {name}", f"Kd {col[0]} {col[1]} {col[2]}"]
    if kind == "textured":
        tex = f"tex_{len(textures)}.png"
        texture(rng, os.path.join(tex_dir, tex))
        textures.append(tex)
        lines.append(f"map_Kd {tex}")
    if kind == "glossy":
        lines += ["Ks 1 1 1", f"Pr {round(rng.uniform(0.03, 0.4), 3)}"]
    if kind == "metal":
        lines += ["Pm 1", f"Pr {round(rng.uniform(0.05, 0.5), 3)}"]
    if kind in ("diffuse", "textured"):
        lines.append("Pr 1")
    return "\n".join(lines)


def room(seed, out):
    rng = random.Random(seed)
    os.makedirs(out, exist_ok=True)
    W, H, D = rng.uniform(4, 9), rng.uniform(2.6, 4), rng.uniform(4, 9)
    textures, mats = [], []
    mesh = Mesh()
    for m in ["floor", "wall_a", "wall_b", "ceiling"] + [f"obj_{i}" for i in range(8)]:
        mats.append(material(rng, m, out, textures))
    windowed = rng.random() < 0.5
    # Floor, ceiling, four walls (inward facing). A windowed room has a hole in one wall
    # (the wall is built from four quads around it); a closed room has ceiling lights.
    window = None
    if windowed:
        x0, x1 = sorted(rng.uniform(0.5, W - 0.5) for _ in range(2))
        x1 = max(x1, x0 + 1.0)
        window = (x0, x1, 0.8, min(H - 0.3, 0.8 + rng.uniform(1.0, 2.0)))
    mesh.room_shell("floor", "wall_a", "wall_b", "ceiling", W, H, D, window)
    if not windowed:
        for i in range(rng.randint(1, 3)):
            cx, cz = rng.uniform(1, W - 1), rng.uniform(1, D - 1)
            s = rng.uniform(0.2, 0.6)
            mesh.quad("light", (cx - s, H - 0.01, cz - s), (cx + s, H - 0.01, cz - s), (cx + s, H - 0.01, cz + s),
                      (cx - s, H - 0.01, cz + s))
        e = rng.uniform(4, 15)
        tint = [round(e * rng.uniform(0.8, 1.0), 3) for _ in range(3)]
        mats.append(f"newmtl light\nKd 0 0 0\nKe {tint[0]} {tint[1]} {tint[2]}")
    for i in range(rng.randint(4, 12)):
        m = f"obj_{rng.randrange(8)}"
        x, z = rng.uniform(0.6, W - 0.6), rng.uniform(0.6, D - 0.6)
        kind = rng.choice(["box", "box", "sphere", "cylinder"])
        if kind == "box":
            h = (rng.uniform(0.15, 0.6), rng.uniform(0.15, 0.9), rng.uniform(0.15, 0.6))
            stack = rng.random() < 0.2
            mesh.box(m, (x, h[1] + (0.5 if stack else 0), z), h, rng.uniform(0, math.pi), uv_scale=rng.choice([1, 2]))
        elif kind == "sphere":
            r = rng.uniform(0.2, 0.6)
            mesh.surface(m, (x, r, z), r, "sphere", seg=32)
        else:
            r = rng.uniform(0.1, 0.4)
            mesh.surface(m, (x, 0, z), r, "cylinder", seg=24, height=rng.uniform(0.5, 2.0))
    with open(os.path.join(out, "room.mtl"), "w") as f:
        f.write("\n\n".join(mats) + "\n")
    with open(os.path.join(out, "room.obj"), "w") as f:
        f.write(f"# kestrel procedural room, seed {seed}\nmtllib room.mtl\n")
        for v in mesh.v:
            f.write("v %.5f %.5f %.5f\n" % v)
        for t in mesh.vt:
            f.write("vt %.5f %.5f\n" % t)
        for mat, faces in mesh.groups:
            f.write(f"usemtl {mat}\n")
            for tri in faces:
                f.write("f " + " ".join(f"{v + 1}/{t + 1}" for v, t in tri) + "\n")
    # A short walk: 4 keys, eye at head height, looking across the room; the whole path
    # is short so that consecutive frames of a clip overlap (a few pixels of motion).
    eye = [rng.uniform(0.8, W - 0.8), rng.uniform(1.0, min(2.0, H - 0.5)), rng.uniform(0.8, D - 0.8)]
    look = [rng.uniform(0.3, W - 0.3), rng.uniform(0.3, 1.5), rng.uniform(0.3, D - 0.3)]
    if math.dist(eye, look) < 1.5:
        look = [W - eye[0], 0.5, D - eye[2]]
    step = [rng.uniform(-0.25, 0.25), rng.uniform(-0.05, 0.05), rng.uniform(-0.25, 0.25)]
    turn = [rng.uniform(-0.6, 0.6), rng.uniform(-0.2, 0.2), rng.uniform(-0.6, 0.6)]
    vfov = rng.uniform(55, 80)
    keys = []
    for k in range(4):
        keys.append({"time": k / 3, "eye": [eye[i] + step[i] * k for i in range(3)],
                     "target": [look[i] + turn[i] * k for i in range(3)], "vfov": vfov})
    with open(os.path.join(out, "path.json"), "w") as f:
        json.dump({"scene": f"procedural room {seed}", "keyframes": keys}, f, indent=1)
    with open(os.path.join(out, "env.txt"), "w") as f:
        f.write("sky\n" if windowed else "none\n")


if __name__ == "__main__":
    room(int(sys.argv[1]), sys.argv[2])
