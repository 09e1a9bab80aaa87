#!/usr/bin/env python3
"""kestrel from Python, end to end: trace rays against a scene built from numpy arrays,
render a scene's AOVs, denoise the 1-spp colour, and plot it all with matplotlib.

    PYTHONPATH=build/release/python python3 examples/python/trace_and_render.py [SCENE] [-o out.png]
"""
import argparse

import matplotlib

matplotlib.use("Agg")  # no display needed
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

import kestrel  # noqa: E402


def main():
    p = argparse.ArgumentParser()
    p.add_argument("scene", nargs="?", default="builtin:cornell_box")
    p.add_argument("--res", type=int, nargs=2, default=(320, 180))
    p.add_argument("-o", "--out", default="kestrel_aovs.png")
    a = p.parse_args()
    res = tuple(a.res)

    # 1. Geometry from numpy: a height field as two triangles per cell, traced from above.
    n = 64
    x, z = np.meshgrid(np.linspace(-1, 1, n), np.linspace(-1, 1, n))
    y = 0.2 * np.sin(3 * x) * np.cos(2 * z)
    vertices = np.stack([x, y, z], axis=-1).reshape(-1, 3).astype(np.float32)
    i = np.arange(n * n).reshape(n, n)[:-1, :-1].reshape(-1)
    indices = np.concatenate([np.stack([i, i + n, i + 1], 1), np.stack([i + 1, i + n, i + n + 1], 1)]).astype(np.uint32)
    terrain = kestrel.Scene.from_arrays(vertices, indices, name="terrain")
    accel = kestrel.build_accel(terrain, quality="high")
    print(accel, kestrel.bvh_metrics(terrain, quality="high")["sah_cost"])
    grid = np.stack(np.meshgrid(np.linspace(-1, 1, 200), np.linspace(-1, 1, 200)), -1).reshape(-1, 2)
    origins = np.column_stack([grid[:, 0], np.full(len(grid), 2.0), grid[:, 1]])
    rays = kestrel.rays_array(origins, np.tile([0.0, -1.0, 0.0], (len(grid), 1)))
    hits = kestrel.trace(accel, rays)
    height = np.where(np.isfinite(hits["t"]), 2.0 - hits["t"], np.nan).reshape(200, 200)

    # 2. A scene's AOVs, 1 spp and 64 spp, and the 1-spp frame denoised.
    scene = kestrel.load_scene(a.scene)
    renderer = kestrel.Renderer(scene)
    camera = kestrel.view(scene)
    noisy = renderer.render(camera, spp=1, res=res)
    clean = renderer.render(camera, spp=64, res=res)
    denoised = kestrel.denoise(noisy["color"], albedo=noisy["albedo"], normal=noisy["normal"], depth=noisy["depth"],
                               roughness=noisy["roughness"], motion=noisy["motion"])

    panels = [
        ("height field (traced)", height, "viridis"),
        ("albedo", noisy["albedo"], None),
        ("normal", 0.5 + 0.5 * noisy["normal"], None),
        ("depth", noisy["depth"][..., 0], "magma"),
        ("1 spp", kestrel.tonemap(noisy["color"]), None),
        ("1 spp, denoised", kestrel.tonemap(denoised), None),
        ("64 spp", kestrel.tonemap(clean["color"]), None),
        ("64 spp: variance of the mean", np.log10(1e-6 + clean["variance"][..., 0]), "inferno"),
    ]
    fig, axes = plt.subplots(2, 4, figsize=(16, 5.5))
    for ax, (title, image, cmap) in zip(axes.flat, panels):
        ax.imshow(np.clip(image, 0, 1) if image.ndim == 3 and image.dtype != np.uint8 else image, cmap=cmap)
        ax.set_title(title)
        ax.axis("off")
    fig.tight_layout()
    fig.savefig(a.out, dpi=80)
    print(f"wrote {a.out}")


if __name__ == "__main__":
    main()
