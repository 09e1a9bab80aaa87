#!/usr/bin/env python3
"""A generated scene as glTF 2.0 (scene.gltf + scene.bin), for scenes with moving objects.

families.py builds its scenes as procedural.Mesh objects with MTL materials and writes them as
OBJ; an OBJ cannot move, so a scene with animated objects is written here instead: the static
geometry as one mesh at an identity node, each moving object as a mesh of its own at a node
whose translation and rotation are keyframed (LINEAR samplers), which `kestrel
render-sequence` poses per frame (motion vectors included). Materials are the MTL ones,
mapped so that kestrel's glTF loader gives the same Material as its MTL loader:

    Kd -> baseColorFactor          map_Kd -> baseColorTexture (OBJ v flipped: glTF's v is down)
    Pm -> metallicFactor           Pr -> roughnessFactor (without Pr and Pm: sqrt(2 / (Ns + 2)),
    Ks -> KHR_materials_specular         tinyobjloader's Ns default 1)
    Ke -> emissiveFactor / KHR_materials_emissive_strength

The check is the renderer itself: tests/denoise/families_smoke.sh writes a static scene both
ways (families.py --gltf) and asks for the same frames.
"""
import json
import math
import os
import struct

FLOAT, UINT = 5126, 5125
ARRAY_BUFFER, ELEMENT_ARRAY_BUFFER = 34962, 34963


def parse_mtl(text):
    """One MTL material's text -> dict of its fields (floats / lists / the texture name)."""
    out = {}
    for line in text.splitlines():
        parts = line.split()
        if not parts or parts[0] == "newmtl":
            continue
        key, vals = parts[0], parts[1:]
        out[key] = vals[0] if key.startswith("map_") else [float(v) for v in vals]
    return out


def gltf_material(name, mtl_text, texture_index):
    """The glTF material that kestrel loads as the MTL text's material (see the module doc)."""
    f = parse_mtl(mtl_text)
    kd = f.get("Kd", [0.8, 0.8, 0.8])
    pbr = {"baseColorFactor": [kd[0], kd[1], kd[2], 1.0]}
    metallic = f.get("Pm", [0.0])[0]
    rough = f.get("Pr", [0.0])[0]
    if rough <= 0 and metallic <= 0:  # the MTL loader's rule: roughness from Ns (default 1)
        rough = min(max(math.sqrt(2.0 / (f.get("Ns", [1.0])[0] + 2.0)), 0.0), 1.0)
    pbr["metallicFactor"], pbr["roughnessFactor"] = metallic, rough
    if "map_Kd" in f:
        pbr["baseColorTexture"] = {"index": texture_index(f["map_Kd"])}
    m = {"name": name, "pbrMetallicRoughness": pbr, "doubleSided": True,
         "extensions": {"KHR_materials_specular": {"specularFactor": min(max(max(f.get("Ks", [0.0])), 0.0), 1.0)}}}
    ke = f.get("Ke")
    if ke and max(ke) > 0:
        top = max(ke)
        m["emissiveFactor"] = [k / top for k in ke]
        m["extensions"]["KHR_materials_emissive_strength"] = {"emissiveStrength": top}
    return m


class _Buffer:
    def __init__(self):
        self.data, self.views, self.accessors = bytearray(), [], []

    def add(self, fmt, values, count, kind, target=None, minmax=False):
        while len(self.data) % 4:
            self.data.append(0)
        raw = struct.pack("<" + fmt * len(values), *values)
        view = {"buffer": 0, "byteOffset": len(self.data), "byteLength": len(raw)}
        if target:
            view["target"] = target
        self.data += raw
        self.views.append(view)
        acc = {"bufferView": len(self.views) - 1, "componentType": FLOAT if fmt == "f" else UINT,
               "count": count, "type": kind}
        if minmax:
            n = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4}[kind]
            acc["min"] = [min(values[i::n]) for i in range(n)]
            acc["max"] = [max(values[i::n]) for i in range(n)]
        self.accessors.append(acc)
        return len(self.accessors) - 1


def _mesh(buf, mesh, material_index, name):
    """procedural.Mesh -> a glTF mesh, one primitive per material, corners deduplicated."""
    by_mat = {}
    for mat, faces in mesh.groups:
        by_mat.setdefault(mat, []).extend(faces)
    prims = []
    for mat, faces in by_mat.items():
        corner, pos, uv, idx = {}, [], [], []
        for tri in faces:
            for vi, ti in tri:
                k = (vi, ti)
                if k not in corner:
                    corner[k] = len(corner)
                    pos += [float("%.5f" % c) for c in mesh.v[vi]]  # as families.py's OBJ has them
                    u, v = (float("%.5f" % c) for c in mesh.vt[ti])
                    uv += (u, 1.0 - v)
                idx.append(corner[k])
        prims.append({"attributes": {"POSITION": buf.add("f", pos, len(corner), "VEC3", ARRAY_BUFFER, minmax=True),
                                     "TEXCOORD_0": buf.add("f", uv, len(corner), "VEC2", ARRAY_BUFFER)},
                      "indices": buf.add("I", idx, len(idx), "SCALAR", ELEMENT_ARRAY_BUFFER),
                      "material": material_index[mat], "mode": 4})
    return {"name": name, "primitives": prims}


def yaw_quaternion(angle):
    """A rotation by `angle` radians about +y as glTF's (x, y, z, w)."""
    return [0.0, math.sin(angle / 2), 0.0, math.cos(angle / 2)]


def write(path_gltf, static_mesh, movers, mtl_by_name, comment=""):
    """Writes path_gltf and its .bin beside it. movers: dicts of `mesh` (procedural.Mesh in the
    object's own frame), `name`, `times` (seconds, increasing), `translations` ([x, y, z] per
    time) and `yaws` (radians per time)."""
    buf = _Buffer()
    names = list(mtl_by_name)
    material_index = {n: i for i, n in enumerate(names)}
    images, textures = [], []

    def texture_index(uri):
        if uri not in images:
            images.append(uri)
            textures.append({"source": len(images) - 1, "sampler": 0})
        return images.index(uri)
    materials = [gltf_material(n, mtl_by_name[n], texture_index) for n in names]
    meshes = [_mesh(buf, static_mesh, material_index, "static")]
    nodes = [{"name": "static", "mesh": 0}]
    channels, samplers = [], []
    for mv in movers:
        meshes.append(_mesh(buf, mv["mesh"], material_index, mv["name"]))
        node = len(nodes)
        nodes.append({"name": mv["name"], "mesh": len(meshes) - 1,
                      "translation": list(mv["translations"][0]), "rotation": yaw_quaternion(mv["yaws"][0])})
        t = buf.add("f", mv["times"], len(mv["times"]), "SCALAR", minmax=True)
        tr = buf.add("f", [c for p in mv["translations"] for c in p], len(mv["times"]), "VEC3")
        rot = buf.add("f", [c for a in mv["yaws"] for c in yaw_quaternion(a)], len(mv["times"]), "VEC4")
        for path, out in (("translation", tr), ("rotation", rot)):
            samplers.append({"input": t, "output": out, "interpolation": "LINEAR"})
            channels.append({"sampler": len(samplers) - 1, "target": {"node": node, "path": path}})
    bin_path = os.path.splitext(path_gltf)[0] + ".bin"
    bin_name = os.path.basename(bin_path)
    doc = {"asset": {"version": "2.0", "generator": "kestrel scripts/denoise/families.py" + (f" ({comment})" if comment else "")},
           "extensionsUsed": ["KHR_materials_specular", "KHR_materials_emissive_strength"],
           "scene": 0, "scenes": [{"nodes": list(range(len(nodes)))}], "nodes": nodes, "meshes": meshes,
           "materials": materials, "buffers": [{"uri": bin_name, "byteLength": len(buf.data)}],
           "bufferViews": buf.views, "accessors": buf.accessors}
    if images:
        doc["images"] = [{"uri": u} for u in images]
        doc["textures"] = textures
        doc["samplers"] = [{"magFilter": 9729, "minFilter": 9729, "wrapS": 10497, "wrapT": 10497}]
    if channels:
        doc["animations"] = [{"name": "movers", "channels": channels, "samplers": samplers}]
    with open(bin_path, "wb") as f:
        f.write(bytes(buf.data))
    with open(path_gltf, "w") as f:
        json.dump(doc, f, indent=1)
