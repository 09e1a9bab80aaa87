"""Shared fixtures: the kestrel CLI (the oracle the bindings are compared with) and scenes."""
import os
import pathlib
import subprocess

import numpy as np
import pytest

import kestrel

ROOT = pathlib.Path(__file__).resolve().parents[2]


def cli_path():
    path = os.environ.get("KESTREL_CLI")
    if path:
        return path
    for build in ("build/release", "build"):
        candidate = ROOT / build / "apps" / "kestrel" / "kestrel"
        if candidate.exists():
            return str(candidate)
    pytest.skip("the kestrel CLI was not found (set KESTREL_CLI)")


@pytest.fixture(scope="session")
def cli():
    path = cli_path()

    def run(*args):
        result = subprocess.run([path, *map(str, args)], capture_output=True, text=True)
        assert result.returncode == 0, f"kestrel {' '.join(map(str, args))} failed:\n{result.stderr}"
        return result.stdout

    return run


def write_obj(path, vertices, indices):
    with open(path, "w") as f:
        for v in vertices:
            f.write(f"v {float(v[0])!r} {float(v[1])!r} {float(v[2])!r}\n")
        for t in indices:
            f.write(f"f {t[0] + 1} {t[1] + 1} {t[2] + 1}\n")


def triangle_soup(seed, count=2000):
    """Random triangles in the unit cube: vertices (3 count, 3) float32, indices (count, 3) uint32.

    Coordinates are float32 values printed exactly (repr of a float32 widened to float64), so an
    OBJ written from them loads to the same bits."""
    rng = np.random.default_rng(seed)
    centres = rng.random((count, 1, 3))
    vertices = (centres + 0.08 * (rng.random((count, 3, 3)) - 0.5)).reshape(-1, 3).astype(np.float32)
    indices = np.arange(3 * count, dtype=np.uint32).reshape(-1, 3)
    return vertices, indices


def random_rays(seed, count, lo=-0.2, hi=1.2, tmax=np.inf):
    """Incoherent rays: origins in a box around the scene, directions uniform on the sphere."""
    rng = np.random.default_rng(seed)
    origins = rng.uniform(lo, hi, (count, 3))
    directions = rng.normal(size=(count, 3))
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    return kestrel.rays_array(origins, directions, 0.0, tmax)


def bits(a):
    """The raw bits of a float32 array (NaN-safe, -0 vs 0 distinguished)."""
    return np.ascontiguousarray(a, dtype=np.float32).view(np.uint32)
