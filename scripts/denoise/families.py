#!/usr/bin/env python3
"""Seeded procedural scene *families* for training and judging the reconstruction networks.
Each family has many variations (sizes, materials, textures, lights, exposure, camera speed);
everything follows from (family, seed). A scene is an OBJ + MTL (+ PNG textures, + a lights
file), a camera path and the `kestrel render-sequence` flags that light it.

    families.py FAMILY SEED OUT_DIR     -> OUT_DIR/scene.obj, scene.mtl, path.json, render.json
    families.py --list                  -> the families and their split (train / heldout)

Families (TRAIN are used for training; HELDOUT are never seen in training and are kept for
evaluation, with the shared scenes):
  sunlit_interior  rooms lit by sun and sky through windows (white, coloured or textured walls)
  night_interior   closed rooms lit by many small point lights and lamps
  corridor         long corridors under rows of ceiling panels, doors, a walk along them
  outdoor          ground, buildings and foliage cards (thin alpha-less quads) under sun and sky
  product          glossy and metallic objects on a sweep backdrop under softboxes, orbiting
  mirror_room      (heldout) mirrors, mirror spheres and clear-coated objects, window or lamps
  stairwell        (heldout) flights of steps, railings of thin bars, a skylight and a lamp
  gallery          (heldout) photo-like textured canvases on walls, spot-lit, a slow pan
Variations common to all: exposure (light intensity scaled by 1/8 .. 8: overexposed and very
dark frames), camera speed (slow: a few pixels per frame; fast: tens), untextured / checker /
noise / photo-like textures; and in half of the training families' scenes 1-3 animated objects
(add_movers: sliding, spinning, hopping or flying boxes and spheres), written as glTF
(gltf_scene.py) since an OBJ cannot move.

    families.py --movers FAMILY SEED OUT_DIR     with animated objects whatever the family
    families.py --no-movers FAMILY SEED OUT_DIR  without
    families.py --gltf FAMILY SEED OUT_DIR       without, as glTF (the OBJ / glTF check)
"""
import json
import math
import os
import random
import sys

from PIL import Image

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from procedural import Mesh, texture  # noqa: E402
import gltf_scene  # noqa: E402

TRAIN = ["sunlit_interior", "night_interior", "corridor", "outdoor", "product"]
HELDOUT = ["mirror_room", "stairwell", "gallery"]
CAMERA_MARGIN = 0.25  # metres between a walking camera and the first room's walls, floor and ceiling
OBJECT_MARGIN = 0.1  # and between it and an object's bounding box


class Scene:
    def __init__(self, rng, out):
        self.rng, self.out = rng, out
        self.mesh, self.mats, self.textures, self.lights = Mesh(), {}, [], []
        self.flags = []
        self.bounds = None  # the first room's (W, H, D): the camera stays inside it
        self.movers = []  # animated objects (add_movers): the scene is then written as glTF
        self.as_gltf = False  # write glTF even without movers (the OBJ / glTF equivalence check)
        os.makedirs(out, exist_ok=True)

    # Materials: MTL text per name.
    def mat(self, name, kind=None, color=None):
        rng = self.rng
        if name in self.mats:
            return name
        kind = kind or rng.choices(["diffuse", "textured", "photo", "glossy", "metal"], [4, 2, 1, 2, 1])[0]
        col = color or [round(rng.uniform(0.05, 0.9), 3) for _ in range(3)]
        lines = [f"newmtl {name}", f"Kd {col[0]} {col[1]} {col[2]}"]
        if kind in ("textured", "photo"):
            tex = f"tex_{len(self.textures)}.png"
            (photo_texture if kind == "photo" else texture)(rng, os.path.join(self.out, tex))
            self.textures.append(tex)
            lines += [f"map_Kd {tex}", "Pr 1"]
        elif kind == "glossy":
            lines += ["Ks 1 1 1", f"Pr {round(rng.uniform(0.02, 0.35), 3)}"]
        elif kind == "coated":  # clear coat over a saturated base: glass-like reflections
            lines += ["Ks 1 1 1", "Pr 0.0"]
        elif kind == "metal":
            lines += ["Pm 1", f"Pr {round(rng.uniform(0.05, 0.5), 3)}"]
        elif kind == "mirror":
            lines = [f"newmtl {name}", "Kd 0.95 0.95 0.95", "Pm 1", "Pr 0.0"]
        elif kind == "gold":
            lines = [f"newmtl {name}", "Kd 1.0 0.78 0.34", "Pm 1", f"Pr {round(rng.uniform(0.0, 0.25), 3)}"]
        elif kind == "emitter":
            e = [round(c, 3) for c in col]
            lines = [f"newmtl {name}", "Kd 0 0 0", f"Ke {e[0]} {e[1]} {e[2]}"]
        else:
            lines.append("Pr 1")
        self.mats[name] = "\n".join(lines)
        return name

    def room(self, W, H, D, window=None, prefix="room"):
        """An inward-facing box room; window = (x0, x1, y0, y1) cut into the z = D wall."""
        floor, wall, ceil = (self.mat(f"{prefix}_floor"), self.mat(f"{prefix}_wall"), self.mat(f"{prefix}_ceiling", "diffuse"))
        self.mesh.room_shell(floor, wall, wall, ceil, W, H, D, window)
        if self.bounds is None:
            self.bounds = (W, H, D)

    def clutter(self, W, D, n, kinds=("box", "box", "sphere", "cylinder"), mats=None, margin=0.6):
        rng, m = self.rng, self.mesh
        for i in range(n):
            mat = self.mat(rng.choice(mats) if mats else f"obj_{rng.randrange(6)}")
            x, z = rng.uniform(margin, W - margin), rng.uniform(margin, D - margin)
            kind = rng.choice(kinds)
            if kind == "box":
                h = (rng.uniform(0.15, 0.6), rng.uniform(0.15, 0.9), rng.uniform(0.15, 0.6))
                m.box(mat, (x, h[1], z), h, rng.uniform(0, math.pi), uv_scale=rng.choice([1, 2]))
            elif kind == "sphere":
                r = rng.uniform(0.2, 0.6)
                m.surface(mat, (x, r, z), r, "sphere", seg=32)
            else:
                r = rng.uniform(0.05, 0.4)
                m.surface(mat, (x, 0, z), r, "cylinder", seg=20, height=rng.uniform(0.5, 2.0))

    def point_light(self, p, color, intensity):
        self.lights.append({"name": f"lamp_{len(self.lights)}", "type": "point", "position": [round(v, 4) for v in p],
                            "color": color, "intensity": round(intensity, 4)})

    def walk(self, eye, look, speed, vfov, frames_span=1.0):
        """A 4-key path: eye moves by `speed` metres over the clip, the target drifts."""
        rng = self.rng
        a = rng.uniform(0, 2 * math.pi)
        step = [math.cos(a) * speed / 3, rng.uniform(-0.02, 0.02), math.sin(a) * speed / 3]
        turn = [rng.uniform(-1, 1) * speed / 3, rng.uniform(-0.1, 0.1) * speed, rng.uniform(-1, 1) * speed / 3]
        keys = [{"time": k / 3 * frames_span, "eye": [eye[i] + step[i] * k for i in range(3)],
                 "target": [look[i] + turn[i] * k for i in range(3)], "vfov": vfov} for k in range(4)]
        self.path = {"keyframes": keys}

    def keep_camera_free(self):
        """A walk must not leave the room nor pass through an object (its frames came out
        black: 7 of a stairwell clip's 16 behind a wall, 4 of a mirror room's inside a box).
        The keyframes' eyes are kept inside the first room; a path that still meets an
        object (OBJECT_MARGIN around its bounding box) is shortened towards its first eye."""
        keys = self.path["keyframes"]
        if self.bounds is not None:
            for key in keys:
                key["eye"] = [min(max(v, CAMERA_MARGIN), b - CAMERA_MARGIN) for v, b in zip(key["eye"], self.bounds)]

        def blocked(eyes):
            for a, b in zip(eyes, eyes[1:]):
                for k in range(17):
                    p = [a[i] + (b[i] - a[i]) * k / 16 for i in range(3)]
                    for lo, hi in self.mesh.solids:
                        if all(lo[i] - OBJECT_MARGIN < p[i] < hi[i] + OBJECT_MARGIN for i in range(3)):
                            return True
            return False
        start = keys[0]["eye"]
        if not blocked([key["eye"] for key in keys]):
            return
        for f in (0.75, 0.5, 0.25, 0.0):
            eyes = [[s + (e - s) * f for s, e in zip(start, key["eye"])] for key in keys]
            if not blocked(eyes):
                for key, eye in zip(keys, eyes):
                    key["eye"] = eye
                return
        if any(all(lo[i] < start[i] < hi[i] for i in range(3)) for lo, hi in self.mesh.solids):
            print(f"families.py: {self.out}: the camera starts inside an object", file=sys.stderr)

    def write_obj(self, family, seed):
        obj, mtl = os.path.join(self.out, "scene.obj"), os.path.join(self.out, "scene.mtl")
        with open(mtl, "w") as f:
            f.write("\n\n".join(self.mats.values()) + "\n")
        with open(obj, "w") as f:
            f.write(f"# kestrel scene family {family}, seed {seed}\nmtllib scene.mtl\n")
            for v in self.mesh.v:
                f.write("v %.5f %.5f %.5f\n" % v)
            for t in self.mesh.vt:
                f.write("vt %.5f %.5f\n" % t)
            for mat, faces in self.mesh.groups:
                f.write(f"usemtl {mat}\n")
                for tri in faces:
                    f.write("f " + " ".join(f"{v + 1}/{t + 1}" for v, t in tri) + "\n")
        return obj

    def write(self, family, seed, exposure):
        if self.movers or self.as_gltf:
            scene = os.path.join(self.out, "scene.gltf")
            gltf_scene.write(scene, self.mesh, self.movers, self.mats, comment=f"{family} {seed}")
        else:
            scene = self.write_obj(family, seed)
        flags = list(self.flags)
        if self.lights:
            for L in self.lights:
                L["intensity"] = round(L["intensity"] * exposure, 5)
            json.dump({"lights": self.lights}, open(os.path.join(self.out, "lights.json"), "w"), indent=1)
            flags += ["--lights", os.path.join(self.out, "lights.json"), "--light-sampling", "tree"]
        self.keep_camera_free()
        self.path["scene"] = f"{family} {seed}"
        json.dump(self.path, open(os.path.join(self.out, "path.json"), "w"), indent=1)
        triangles = sum(len(g[1]) for m in [self.mesh] + [mv["mesh"] for mv in self.movers] for g in m.groups)
        info = {"family": family, "seed": seed, "exposure": exposure, "flags": flags, "scene": scene,
                "path": os.path.join(self.out, "path.json"), "triangles": triangles, "movers": len(self.movers)}
        json.dump(info, open(os.path.join(self.out, "render.json"), "w"), indent=1)
        return info


def photo_texture(rng, path, n=256):
    """Photo-like: a few octaves of smooth value noise in two random colours, with edges."""
    base = [[rng.random() for _ in range(9)] for _ in range(9)]
    a = [rng.uniform(0.05, 0.9) for _ in range(3)]
    b = [rng.uniform(0.05, 0.9) for _ in range(3)]
    octaves = [(rng.randint(2, 5), 0.55), (rng.randint(8, 16), 0.3), (rng.randint(24, 48), 0.15)]
    grids = [[[rng.random() for _ in range(k + 1)] for _ in range(k + 1)] for k, _ in octaves]
    img = Image.new("RGB", (n, n))
    px = img.load()
    for y in range(n):
        for x in range(n):
            v = 0.0
            for (k, w), g in zip(octaves, grids):
                fx, fy = x / n * k, y / n * k
                i, j = int(fx), int(fy)
                tx, ty = fx - i, fy - j
                tx, ty = tx * tx * (3 - 2 * tx), ty * ty * (3 - 2 * ty)
                top = g[j][i] * (1 - tx) + g[j][i + 1] * tx
                bot = g[j + 1][i] * (1 - tx) + g[j + 1][i + 1] * tx
                v += w * (top * (1 - ty) + bot * ty)
            v = min(max((v - 0.2) / 0.6, 0.0), 1.0)
            px[x, y] = tuple(int(255 * (a[c] * (1 - v) + b[c] * v)) for c in range(3))
    del base
    img.save(path)


def exposure_and_speed(rng):
    exposure = 2.0 ** rng.choice([-3, -2, -1, 0, 0, 0, 1, 2, 3])
    speed = rng.choice([0.15, 0.3, 0.6, 1.5, 3.0])  # metres over the clip: slow .. fast
    return exposure, speed


def sun_through(rng, exposure, elevation=(15, 50)):
    """A sun on the +Z side (the windows' side): azimuth 180 +- 60 (north is -Z)."""
    az, el = 180 + rng.uniform(-60, 60), rng.uniform(*elevation)
    return ["--sun", f"{az:.1f},{el:.1f},{rng.uniform(4, 12) * exposure:.3f}", "--sky"]


def sunlit_interior(s, rng, exposure, speed):
    W, H, D = rng.uniform(4, 9), rng.uniform(2.6, 4), rng.uniform(4, 9)
    x0 = rng.uniform(0.4, W / 2)
    win = (x0, min(W - 0.4, x0 + rng.uniform(0.8, 2.5)), rng.uniform(0.5, 1.0), 0)
    win = (win[0], win[1], win[2], min(H - 0.2, win[2] + rng.uniform(1.0, 2.2)))
    if rng.random() < 0.4:
        s.mat("room_wall", "diffuse", [0.85, 0.85, 0.85])
    s.room(W, H, D, window=win)
    s.clutter(W, D, rng.randint(3, 10))
    if rng.random() < 0.5:
        r = rng.uniform(0.25, 0.6)
        s.mesh.surface(s.mat("mirror_ball", "mirror"), (rng.uniform(1, W - 1), r, rng.uniform(1, D - 1)), r, "sphere", seg=40)
    s.flags = sun_through(rng, exposure)
    eye = [rng.uniform(0.8, W - 0.8), rng.uniform(1.0, min(2.0, H - 0.4)), rng.uniform(0.6, D * 0.5)]
    s.walk(eye, [rng.uniform(0.3, W - 0.3), rng.uniform(0.3, 1.5), D - rng.uniform(0.5, 3)], speed, rng.uniform(55, 80))


def night_interior(s, rng, exposure, speed):
    W, H, D = rng.uniform(4, 10), rng.uniform(2.5, 3.5), rng.uniform(4, 10)
    s.room(W, H, D)
    s.clutter(W, D, rng.randint(4, 12))
    warm = [1.0, round(rng.uniform(0.55, 0.85), 3), round(rng.uniform(0.3, 0.6), 3)]
    for i in range(rng.randint(8, 60)):
        p = (rng.uniform(0.2, W - 0.2), rng.uniform(0.3, H - 0.1), rng.uniform(0.2, D - 0.2))
        s.point_light(p, warm, rng.uniform(0.05, 0.6))
    for i in range(rng.randint(0, 3)):  # small emissive lamp shades
        r = rng.uniform(0.05, 0.15)
        s.mesh.surface(s.mat(f"lamp_{i}", "emitter", [rng.uniform(5, 30) * exposure] * 3),
                       (rng.uniform(0.5, W - 0.5), rng.uniform(0.8, H - 0.3), rng.uniform(0.5, D - 0.5)), r, "sphere", seg=12)
    s.flags = ["--env", "none"]
    eye = [rng.uniform(0.8, W - 0.8), rng.uniform(1.0, 1.8), rng.uniform(0.8, D - 0.8)]
    s.walk(eye, [W - eye[0], 0.7, D - eye[2]], speed, rng.uniform(55, 80))


def corridor(s, rng, exposure, speed):
    W, H, D = rng.uniform(1.8, 3.2), rng.uniform(2.4, 3.2), rng.uniform(14, 30)
    s.room(W, H, D)
    panel = s.mat("panel", "emitter", [rng.uniform(4, 12) * exposure] * 3)
    gap = rng.uniform(2, 5)
    z = gap / 2
    while z < D:
        w, l = rng.uniform(0.3, W * 0.4), rng.uniform(0.4, 1.2)
        c = W / 2
        s.mesh.quad(panel, (c - w, H - 0.01, z - l), (c + w, H - 0.01, z - l), (c + w, H - 0.01, z + l), (c - w, H - 0.01, z + l))
        z += gap
    door = s.mat("door")
    for i in range(rng.randint(2, 8)):
        side = rng.choice([0.02, W - 0.02])
        zc = rng.uniform(1, D - 1)
        s.mesh.box(door, (side, 1.05, zc), (0.03, 1.05, 0.45), 0.0)
    s.flags = ["--env", "none"]
    eye = [W / 2 + rng.uniform(-0.3, 0.3), rng.uniform(1.4, 1.8), rng.uniform(0.8, 3)]
    s.walk(eye, [W / 2 + rng.uniform(-0.5, 0.5), rng.uniform(0.8, 1.6), D - 0.5], speed, rng.uniform(50, 75))
    # Walk along the corridor, not across it.
    for k, key in enumerate(s.path["keyframes"]):
        key["eye"] = [eye[0], eye[1], eye[2] + speed * k / 3]


def outdoor(s, rng, exposure, speed):
    m, size = s.mesh, rng.uniform(30, 60)
    m.quad(s.mat("ground", rng.choice(["textured", "photo", "diffuse"])), (-size, 0, -size), (size, 0, -size), (size, 0, size), (-size, 0, size), uv_scale=size / 2)
    for i in range(rng.randint(3, 12)):
        h = (rng.uniform(1, 4), rng.uniform(2, 12), rng.uniform(1, 4))
        m.box(s.mat(f"building_{i % 4}"), (rng.uniform(-20, 20), h[1], rng.uniform(-25, -4)), h, rng.uniform(0, math.pi))
    leaf = s.mat("foliage", "diffuse", [0.08, round(rng.uniform(0.2, 0.45), 3), 0.05])
    for i in range(rng.randint(2, 8)):  # trees: a trunk and crossed thin cards
        x, z = rng.uniform(-15, 15), rng.uniform(-18, -2)
        m.surface(s.mat("trunk", "diffuse", [0.25, 0.17, 0.1]), (x, 0, z), 0.12, "cylinder", seg=10, height=2.5)
        for k in range(rng.randint(6, 14)):
            a, y, r = rng.uniform(0, math.pi), rng.uniform(1.8, 4), rng.uniform(0.4, 1.2)
            dx, dz = math.cos(a) * r, math.sin(a) * r
            m.quad(leaf, (x - dx, y - 0.3, z - dz), (x + dx, y - 0.3, z + dz), (x + dx, y + 0.3, z + dz), (x - dx, y + 0.3, z - dz))
    s.clutter(8, 8, rng.randint(2, 6), mats=["obj_0", "obj_1", "obj_2"])
    s.flags = ["--sun", f"{rng.uniform(0, 360):.1f},{rng.uniform(8, 70):.1f},{rng.uniform(4, 12) * exposure:.3f}", "--sky"]
    eye = [rng.uniform(-3, 3), rng.uniform(1.2, 2.5), rng.uniform(4, 10)]
    s.walk(eye, [rng.uniform(-5, 5), rng.uniform(1, 4), rng.uniform(-15, -5)], speed * 3, rng.uniform(50, 75))


def product(s, rng, exposure, speed):
    m = s.mesh
    back = s.mat("sweep", "diffuse", [round(rng.uniform(0.05, 0.9), 3)] * 3)
    # A sweep: floor, a quarter-cylinder bend and a back wall, as quads.
    R, n = 1.2, 8
    m.quad(back, (-4, 0, -2 + R), (4, 0, -2 + R), (4, 0, 4), (-4, 0, 4), uv_scale=2)
    for i in range(n):
        a0, a1 = math.pi / 2 * i / n, math.pi / 2 * (i + 1) / n
        p = lambda a, x: (x, R - R * math.cos(a), -2 + R - R * math.sin(a))  # noqa: E731
        m.quad(back, p(a1, -4), p(a1, 4), p(a0, 4), p(a0, -4))
    m.quad(back, (-4, R, -2), (4, R, -2), (4, 5, -2), (-4, 5, -2))
    for i in range(rng.randint(1, 4)):
        kind = rng.choice(["sphere", "sphere", "cylinder", "box"])
        mat = s.mat(f"hero_{i}", rng.choice(["gold", "metal", "glossy", "coated", "mirror"]))
        x, z = rng.uniform(-1.2, 1.2), rng.uniform(-0.5, 1.2)
        if kind == "sphere":
            r = rng.uniform(0.2, 0.5)
            m.surface(mat, (x, r, z), r, "sphere", seg=48)
        elif kind == "cylinder":
            m.surface(mat, (x, 0, z), rng.uniform(0.1, 0.3), "cylinder", seg=32, height=rng.uniform(0.3, 1.0))
        else:
            h = rng.uniform(0.15, 0.35)
            m.box(mat, (x, h, z), (h, h, h), rng.uniform(0, math.pi))
    for i in range(rng.randint(1, 3)):  # softboxes
        e = rng.uniform(3, 15) * exposure
        box = s.mat(f"softbox_{i}", "emitter", [e, e * rng.uniform(0.85, 1), e * rng.uniform(0.7, 1)])
        a, h, r, w = rng.uniform(0, 2 * math.pi), rng.uniform(1.5, 3), rng.uniform(2, 3), rng.uniform(0.3, 0.8)
        cx, cz = math.cos(a) * r, 1 + math.sin(a) * r
        tx, tz = -math.sin(a) * w, math.cos(a) * w
        m.quad(box, (cx - tx, h - w, cz - tz), (cx + tx, h - w, cz + tz), (cx + tx, h + w, cz + tz), (cx - tx, h + w, cz - tz))
    s.flags = ["--env", "constant:0.02,0.02,0.025"] if rng.random() < 0.5 else ["--env", "none"]
    a0 = rng.uniform(0, math.pi)
    dist, h = rng.uniform(2.5, 4), rng.uniform(0.6, 1.8)
    span = speed * 0.4  # radians of orbit over the clip
    keys = [{"time": k / 3, "eye": [math.cos(a0 + span * k / 3) * dist, h, 0.3 + math.sin(a0 + span * k / 3) * dist],
             "target": [0, 0.3, 0.3], "vfov": rng.uniform(30, 50)} for k in range(4)]
    s.path = {"keyframes": keys}


def mirror_room(s, rng, exposure, speed):
    W, H, D = rng.uniform(4, 8), rng.uniform(2.6, 3.6), rng.uniform(4, 8)
    windowed = rng.random() < 0.5
    s.room(W, H, D, window=(W * 0.3, W * 0.6, 0.8, min(H - 0.3, 2.3)) if windowed else None)
    mirror = s.mat("mirror", "mirror")
    m = s.mesh
    for i in range(rng.randint(1, 3)):  # mirror panels on the side walls
        z0 = rng.uniform(0.5, D - 2)
        x = 0.02 if rng.random() < 0.5 else W - 0.02
        zs = (z0, z0 + rng.uniform(0.8, 1.8)) if x < 1 else (z0 + rng.uniform(0.8, 1.8), z0)
        m.quad(mirror, (x, 0.4, zs[0]), (x, 0.4, zs[1]), (x, 2.2, zs[1]), (x, 2.2, zs[0]))
    for i in range(rng.randint(1, 3)):
        r = rng.uniform(0.2, 0.6)
        m.surface(s.mat(f"ball_{i}", rng.choice(["mirror", "coated", "gold"])), (rng.uniform(1, W - 1), r, rng.uniform(1, D - 1)), r, "sphere", seg=40)
    s.clutter(W, D, rng.randint(2, 6))
    if windowed:
        s.flags = sun_through(rng, exposure)
    else:
        for i in range(rng.randint(2, 6)):
            s.point_light((rng.uniform(0.5, W - 0.5), H - 0.3, rng.uniform(0.5, D - 0.5)), [1, 0.9, 0.8], rng.uniform(1, 4))
        s.flags = ["--env", "none"]
    eye = [rng.uniform(0.8, W - 0.8), rng.uniform(1.0, 1.8), rng.uniform(0.6, D * 0.4)]
    s.walk(eye, [rng.uniform(0.5, W - 0.5), 0.6, D - 1], speed, rng.uniform(55, 80))


def stairwell(s, rng, exposure, speed):
    W, H, D = rng.uniform(3, 5), rng.uniform(6, 9), rng.uniform(4, 7)
    s.room(W, H, D)
    m = s.mesh
    step, rail = s.mat("step"), s.mat("rail", rng.choice(["metal", "diffuse"]))
    rise, run, width = rng.uniform(0.15, 0.2), rng.uniform(0.25, 0.32), rng.uniform(1.0, W / 2 - 0.1)
    y, z, flight = 0.0, 0.5, 0
    while y + rise < H - 2:
        n = int(min((D - 1.2) / run, (H - 2 - y) / rise))
        for i in range(n):
            zz = z + i * run if flight % 2 == 0 else D - 0.5 - i * run
            x0 = 0.0 if flight % 2 == 0 else W - width
            m.box(step, (x0 + width / 2, y + rise * (i + 0.5), zz), (width / 2, rise / 2, run / 2), 0.0)
            if i % 2 == 0:  # balusters: thin bars
                m.surface(rail, (x0 + (width if flight % 2 == 0 else 0), y + rise * i, zz), 0.012, "cylinder", seg=6, height=0.9)
        y += n * rise
        flight += 1
        if flight > 3:
            break
    m.surface(s.mat("lamp", "emitter", [rng.uniform(10, 40) * exposure] * 3), (W / 2, H - 0.4, D / 2), 0.15, "sphere", seg=12)
    s.flags = ["--env", "none"]
    eye = [W - 0.6, rng.uniform(1.2, 1.8), rng.uniform(0.6, 1.5)]
    s.walk(eye, [W / 3, rng.uniform(1.5, 4), D - 1], speed, rng.uniform(60, 80))
    for k, key in enumerate(s.path["keyframes"]):  # climb while looking around
        key["eye"][1] = eye[1] + speed * 0.3 * k / 3


def gallery(s, rng, exposure, speed):
    W, H, D = rng.uniform(6, 12), rng.uniform(3, 4.5), rng.uniform(6, 12)
    s.mat("room_wall", "diffuse", [0.8, 0.8, 0.78])
    s.room(W, H, D)
    m = s.mesh
    for i in range(rng.randint(3, 8)):  # canvases on the walls
        canvas = s.mat(f"canvas_{i}", rng.choice(["photo", "photo", "textured"]))
        w, h = rng.uniform(0.5, 1.5), rng.uniform(0.5, 1.2)
        y0 = rng.uniform(1.0, 1.6)
        if rng.random() < 0.5:
            x = rng.uniform(w + 0.3, W - w - 0.3)
            m.quad(canvas, (x + w, y0, 0.03), (x - w, y0, 0.03), (x - w, y0 + h, 0.03), (x + w, y0 + h, 0.03))
        else:
            z = rng.uniform(w + 0.3, D - w - 0.3)
            m.quad(canvas, (0.03, y0, z - w), (0.03, y0, z + w), (0.03, y0 + h, z + w), (0.03, y0 + h, z - w))
        s.point_light((rng.uniform(1, W - 1), H - 0.2, rng.uniform(1, D - 1)), [1, 0.95, 0.85], rng.uniform(0.5, 3))
    s.clutter(W, D, rng.randint(1, 4), kinds=("box", "cylinder"))
    s.flags = ["--env", "none"]
    eye = [rng.uniform(W * 0.4, W * 0.8), rng.uniform(1.4, 1.8), rng.uniform(D * 0.5, D - 1)]
    s.walk(eye, [0.5, 1.4, rng.uniform(1, D - 1)], speed * 0.5, rng.uniform(50, 70))


def mirror_sphere_probe(out):
    """Not a family: the fixed scene of the brightness test (tests/denoise/mirror_bound.sh):
    a white room lit by the sun and sky through one window, a mirror sphere standing in the
    sun patch, a static camera. Its 1-spp frames are full of fireflies (sun paths through the
    mirror), its reference's brightest pixels are the sun's reflection."""
    s = Scene(random.Random("probe"), out)
    W, H, D = 5.0, 3.0, 5.0
    s.mat("room_floor", "diffuse", [0.8, 0.8, 0.8])
    s.mat("room_wall", "diffuse", [0.85, 0.85, 0.85])
    s.mat("room_ceiling", "diffuse", [0.85, 0.85, 0.85])
    s.room(W, H, D, window=(1.5, 3.5, 0.8, 2.4))
    s.mesh.surface(s.mat("mirror_ball", "mirror"), (2.5, 0.5, 3.4), 0.5, "sphere", seg=40)
    s.flags = ["--sun", "180,35,8", "--sky"]
    key = {"eye": [2.5, 1.4, 0.5], "target": [2.5, 0.7, 3.4], "vfov": 65}
    s.path = {"keyframes": [dict(time=0.0, **key), dict(time=1.0, **key)]}
    return s.write("mirror_sphere_probe", 0, 1.0)


FAMILIES = {f.__name__: f for f in [sunlit_interior, night_interior, corridor, outdoor, product, mirror_room, stairwell, gallery]}


def dataset_clips(seeds, test_seeds, shared, test_movers=0):
    """A dataset's clips: the TRAIN families x `seeds` (split train; half of them with moving
    objects), the HELDOUT families x `test_seeds` (seeds from 1000, split test, static), the
    HELDOUT families x `test_movers` with moving objects (seeds from 2000, split test, family
    "<family>_moving" in the evaluation), then the `shared` clips (dicts, split test)."""
    out = []
    for f in TRAIN:
        for s in range(seeds):
            out.append(dict(name=f"{f}_{s:03d}", split="train", family=f, seed=s))
    for f in HELDOUT:
        for s in range(test_seeds):
            out.append(dict(name=f"test_{f}_{1000 + s}", split="test", family=f, seed=1000 + s))
    for f in HELDOUT:
        for s in range(test_movers):
            out.append(dict(name=f"test_{f}_moving_{2000 + s}", split="test", family=f, seed=2000 + s, movers=True))
    return out + [dict(c, split="test") for c in shared]


MOVER_TIMES = [0.0, 0.25, 0.5, 0.75, 1.0, 1.5]  # keys past the clip's end (1): no wrap-around


def add_movers(s, family, seed, movers=None):
    """Animated objects: 1-3 boxes or spheres that slide, spin, hop or fly through the view
    during the clip (a quarter of a metre to two metres over it). From a random stream of
    their own, so a scene's static part is the same with or without them. movers=None: half
    of the training families' scenes have them, the held-out families' none (their test clips
    stay as they were); True / False: always / never."""
    rng = random.Random(f"{family}:{seed}:movers")
    if movers is None:
        movers = family in TRAIN and rng.random() < 0.5
    if not movers:
        return
    keys = s.path["keyframes"]
    eyes = [k["eye"] for k in keys]
    for i in range(rng.randint(1, 3)):
        main_rng, s.rng = s.rng, rng  # the mover's material from the movers' stream too
        mat = s.mat(f"mover_{i}")
        s.rng = main_rng
        kind = rng.choice(["box", "sphere", "sphere"])
        m = Mesh()
        if kind == "box":
            h = (rng.uniform(0.1, 0.4), rng.uniform(0.1, 0.5), rng.uniform(0.1, 0.4))
            m.box(mat, (0, h[1], 0), h, 0.0, uv_scale=rng.choice([1, 2]))
            reach, top = math.hypot(h[0], h[2]), 2 * h[1]
        else:
            r = rng.uniform(0.1, 0.45)
            m.surface(mat, (0, r, 0), r, "sphere", seg=32)
            reach, top = r, 2 * r
        fly = kind == "sphere" and rng.random() < 0.3
        hop = kind == "sphere" and not fly and rng.random() < 0.4
        dist = rng.choice([0.25, 0.5, 1.0, 2.0])  # metres over the clip
        spin = rng.uniform(-math.pi, math.pi) if rng.random() < 0.6 else 0.0
        for _ in range(20):
            e, t = keys[0]["eye"], keys[0]["target"]
            f = rng.uniform(0.3, 0.8)
            p0 = [e[0] + (t[0] - e[0]) * f, rng.uniform(0.4, 1.6) if fly else 0.0, e[2] + (t[2] - e[2]) * f]
            a = rng.uniform(0, 2 * math.pi)
            d = [math.cos(a) * dist, rng.uniform(-0.3, 0.3) * dist if fly else 0.0, math.sin(a) * dist]
            pos = []
            for tk in MOVER_TIMES:
                p = [p0[j] + d[j] * tk for j in range(3)]
                if hop:
                    p[1] = abs(math.sin(math.pi * 2 * tk)) * rng.uniform(0.2, 0.6)
                if s.bounds is not None:  # inside the first room, clear of its walls
                    p = [min(max(p[0], reach + 0.05), s.bounds[0] - reach - 0.05), p[1],
                         min(max(p[2], reach + 0.05), s.bounds[2] - reach - 0.05)]
                    p[1] = min(p[1], s.bounds[1] - top - 0.05)
                pos.append([round(v, 5) for v in p])
            clear = all(math.dist(p, eye) > reach + top + 0.6 for p in pos for eye in eyes)
            if clear:
                break
        else:
            continue  # no place away from the camera: leave this one out
        # The swept box keeps the camera walk (keep_camera_free) out of the object's way.
        s.mesh.solids.append((tuple(min(p[j] for p in pos) - (reach if j != 1 else 0) for j in range(3)),
                              tuple(max(p[j] for p in pos) + (reach if j != 1 else top) for j in range(3))))
        yaws = [round(spin * tk, 5) for tk in MOVER_TIMES]
        s.movers.append({"name": f"mover_{i}", "mesh": m, "times": MOVER_TIMES, "translations": pos, "yaws": yaws})


def make(family, seed, out, movers=None, as_gltf=False):
    rng = random.Random(f"{family}:{seed}")
    s = Scene(rng, out)
    exposure, speed = exposure_and_speed(rng)
    FAMILIES[family](s, rng, exposure, speed)
    add_movers(s, family, seed, movers)
    s.as_gltf = as_gltf
    return s.write(family, seed, exposure)


if __name__ == "__main__":
    if len(sys.argv) == 3 and sys.argv[1] == "--probe":
        print(json.dumps(mirror_sphere_probe(sys.argv[2])))
        sys.exit(0)
    if sys.argv[1:] == ["--list"]:
        for f in FAMILIES:
            print(f, "heldout" if f in HELDOUT else "train")
        sys.exit(0)
    args = sys.argv[1:]
    opts = {"--movers": dict(movers=True), "--no-movers": dict(movers=False),
            "--gltf": dict(movers=False, as_gltf=True)}
    kw = {}
    while args and args[0] in opts:
        kw.update(opts[args.pop(0)])
    if len(args) != 3 or args[0] not in FAMILIES:
        sys.exit("usage: families.py [--movers | --no-movers | --gltf] FAMILY SEED OUT_DIR | --probe OUT_DIR | --list"
                 f"  (families: {', '.join(FAMILIES)}; --gltf: without movers, as glTF)")
    print(json.dumps(make(args[0], int(args[1]), args[2], **kw)))
