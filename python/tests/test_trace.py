"""Geometry and ray queries from Python against independent oracles: the CLI on the same rays
(bit for bit), a float64 brute-force intersector in numpy, and the scalar Bvh2 layout."""
import threading
import time

import numpy as np
import pytest

import kestrel
from conftest import bits, random_rays, triangle_soup, write_obj


@pytest.fixture(scope="module")
def soup(tmp_path_factory):
    vertices, indices = triangle_soup(seed=11)
    path = tmp_path_factory.mktemp("soup") / "soup.obj"
    write_obj(path, vertices, indices)
    return vertices, indices, str(path)


def brute_force(vertices, indices, rays):
    """Closest hit of every ray against every triangle, Moller-Trumbore in float64."""
    tri = vertices[indices].astype(np.float64)  # (M, 3, 3)
    o = rays[:, None, 0:3].astype(np.float64)
    d = rays[:, None, 3:6].astype(np.float64)
    e1 = tri[None, :, 1] - tri[None, :, 0]
    e2 = tri[None, :, 2] - tri[None, :, 0]
    p = np.cross(d, e2)
    det = np.sum(e1 * p, axis=-1)
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = 1.0 / det
        s = o - tri[None, :, 0]
        u = np.sum(s * p, axis=-1) * inv
        q = np.cross(s, e1)
        v = np.sum(d * q, axis=-1) * inv
        t = np.sum(e2 * q, axis=-1) * inv
    ok = (np.abs(det) > 1e-12) & (u >= 0) & (v >= 0) & (u + v <= 1) & (t > rays[:, None, 6]) & (t < rays[:, None, 7])
    t = np.where(ok, t, np.inf)
    best = np.argmin(t, axis=1)
    best_t = t[np.arange(len(rays)), best]
    # The second nearest, to skip rays whose two nearest hits are too close to call.
    t_sorted = np.sort(t, axis=1)
    return best_t, np.where(np.isfinite(best_t), best, kestrel.invalid_id), t_sorted[:, 1]


def test_hits_bit_identical_to_cli(cli, soup, tmp_path):
    vertices, indices, obj = soup
    rays = random_rays(seed=5, count=20000)
    kestrel.write_rays(tmp_path / "r.rays", rays)
    scene = kestrel.load_scene(obj)
    for builder in ("binned", "lbvh", "sweep", "spatial"):
        cli(
            "trace", obj, "--rays", tmp_path / "r.rays", "--hits", tmp_path / "h.hits", "--builder", builder,
            "--repeat", 1)
        expected = kestrel.read_hits(tmp_path / "h.hits")
        hits = kestrel.trace(kestrel.build_accel(scene, builder=builder), rays)
        assert np.array_equal(bits(hits["t"]), bits(expected["t"])), builder
        assert np.array_equal(hits["prim_id"], expected["prim_id"]), builder
    assert np.isfinite(hits["t"]).sum() > 1000  # the rays do hit the soup


def test_any_hit_agrees_with_cli(cli, soup, tmp_path):
    _, _, obj = soup
    rays = random_rays(seed=6, count=5000, tmax=0.3)
    kestrel.write_rays(tmp_path / "r.rays", rays)
    cli("trace", obj, "--rays", tmp_path / "r.rays", "--hits", tmp_path / "h.hits", "--any-hit", "--repeat", 1)
    expected = np.isfinite(kestrel.read_hits(tmp_path / "h.hits")["t"])
    accel = kestrel.build_accel(kestrel.load_scene(obj))
    assert np.array_equal(kestrel.occluded(accel, rays), expected)
    assert 0 < expected.sum() < len(rays)


def test_hits_match_brute_force(soup):
    vertices, indices, _ = soup
    rays = random_rays(seed=7, count=600)
    accel = kestrel.build_accel(kestrel.Scene.from_arrays(vertices, indices))
    hits = kestrel.trace(accel, rays)
    t, prim, second = brute_force(vertices, indices, rays)
    with np.errstate(invalid="ignore"):
        clear = ~np.isfinite(t) | (second - t > 1e-4)  # rays whose nearest hit is unambiguous
    assert clear.sum() > 500
    assert np.array_equal(np.isfinite(hits["t"][clear]), np.isfinite(t[clear]))
    hit = clear & np.isfinite(t)
    assert np.array_equal(hits["prim_id"][hit], prim[hit].astype(np.uint32))
    np.testing.assert_allclose(hits["t"][hit], t[hit], rtol=1e-5, atol=1e-6)
    # barycentrics reproduce the hit point
    tri = vertices[indices[hits["prim_id"][hit]]]
    u, v = hits["u"][hit, None], hits["v"][hit, None]
    point = (1 - u - v) * tri[:, 0] + u * tri[:, 1] + v * tri[:, 2]
    expected = rays[hit, 0:3] + hits["t"][hit, None] * rays[hit, 3:6]
    np.testing.assert_allclose(point, expected, atol=1e-4)


@pytest.mark.parametrize("layout", ["bvh2", "bvh4", "bvh8"])
def test_every_layout_and_isa_gives_the_same_hits(soup, layout):
    vertices, indices, _ = soup
    scene = kestrel.Scene.from_arrays(vertices, indices)
    rays = random_rays(seed=8, count=4000)
    reference = kestrel.trace(kestrel.build_accel(scene, layout="bvh2"), rays, isa="sse2")
    accel = kestrel.build_accel(scene, layout=layout)
    for isa in ("sse2", "avx2", "avx512"):
        if not kestrel.isa_supported(isa):
            continue
        for packets in (False, True):
            for stream in (False, True):  # stream: reordered by origin and direction
                hits = kestrel.trace(accel, rays, isa=isa, packets=packets, stream=stream)
                what = (layout, isa, packets, stream)
                assert np.array_equal(bits(hits["t"]), bits(reference["t"])), what
                assert np.array_equal(hits["prim_id"], reference["prim_id"]), what
        occluded = kestrel.occluded(accel, rays, isa=isa, stream=True)
        assert np.array_equal(occluded, reference["prim_id"] != kestrel.invalid_id), (layout, isa)


def test_rays_are_read_in_place_and_out_is_written_in_place(soup):
    vertices, indices, _ = soup
    accel = kestrel.build_accel(kestrel.Scene.from_arrays(vertices, indices))
    rays = random_rays(seed=9, count=1000)
    hits = kestrel.trace(accel, rays)
    assert kestrel._last_inputs()["rays"] == rays.ctypes.data  # C-contiguous float32: no copy
    out = np.empty(len(rays), dtype=kestrel.hit_dtype)
    again = kestrel.trace(accel, rays, out=out)
    assert kestrel._last_inputs()["out"] == out.ctypes.data
    assert np.shares_memory(again["t"], out) and np.shares_memory(again["prim_id"], out)
    assert np.array_equal(out["prim_id"], hits["prim_id"])
    flags = np.zeros(len(rays), dtype=bool)
    assert kestrel.occluded(accel, rays, out=flags) is not None and np.shares_memory(kestrel.occluded(accel, rays, out=flags), flags)
    # A non-contiguous view is copied once, then traced to the same hits.
    strided = kestrel.trace(accel, rays[::2])
    assert kestrel._last_inputs()["rays"] != rays.ctypes.data
    assert np.array_equal(strided["prim_id"], hits["prim_id"][::2])


def test_threads_do_not_change_hits(soup):
    vertices, indices, _ = soup
    scene = kestrel.Scene.from_arrays(vertices, indices)
    rays = random_rays(seed=10, count=50000)
    one = kestrel.trace(kestrel.build_accel(scene, threads=1), rays, threads=1)
    two = kestrel.trace(kestrel.build_accel(scene, threads=2), rays, threads=2)
    assert np.array_equal(bits(one["t"]), bits(two["t"])) and np.array_equal(one["prim_id"], two["prim_id"])


def test_the_gil_is_released_while_tracing(soup):
    vertices, indices, _ = soup
    accel = kestrel.build_accel(kestrel.Scene.from_arrays(vertices, indices))
    rays = np.tile(random_rays(seed=12, count=100000), (8, 1))
    span = {}

    def work():
        span["start"] = time.perf_counter()
        kestrel.trace(accel, rays, threads=1)
        span["end"] = time.perf_counter()

    worker = threading.Thread(target=work)
    ticks = []
    worker.start()
    while worker.is_alive():
        ticks.append(time.perf_counter())
        time.sleep(0.001)
    worker.join()
    length = span["end"] - span["start"]
    assert length > 0.05, "the batch was too small to tell"
    inside = [t for t in ticks if span["start"] + 0.2 * length < t < span["end"] - 0.2 * length]
    assert len(inside) >= 5, "the main thread did not run while kestrel traced: the GIL was held"


def test_bad_arguments_name_the_argument(soup):
    vertices, indices, _ = soup
    accel = kestrel.build_accel(kestrel.Scene.from_arrays(vertices, indices))
    rays = random_rays(seed=13, count=10)
    with pytest.raises(TypeError, match="rays: expected dtype float32, got float64"):
        kestrel.trace(accel, rays.astype(np.float64))
    with pytest.raises(ValueError, match=r"rays: expected shape \(N, 8\), got \(10, 7\)"):
        kestrel.trace(accel, rays[:, :7])
    with pytest.raises(ValueError, match="rays: expected shape"):
        kestrel.occluded(accel, rays.reshape(-1))
    with pytest.raises(TypeError, match="rays"):
        kestrel.trace(accel, None)
    with pytest.raises(TypeError, match="out: expected dtype"):
        kestrel.trace(accel, rays, out=np.empty(10, dtype=np.float32))
    with pytest.raises(ValueError, match="out: expected shape"):
        kestrel.trace(accel, rays, out=np.empty(11, dtype=kestrel.hit_dtype))
    with pytest.raises(ValueError, match="isa: unknown ISA"):
        kestrel.trace(accel, rays, isa="neon")
    with pytest.raises(ValueError, match="threads"):
        kestrel.trace(accel, rays, threads=-1)
    with pytest.raises(ValueError, match="builder: unknown builder 'fastest'"):
        kestrel.build_accel(kestrel.Scene.from_arrays(vertices, indices), builder="fastest")
    with pytest.raises(ValueError, match="layout"):
        kestrel.build_accel(kestrel.Scene.from_arrays(vertices, indices), layout="bvh16")
    with pytest.raises(ValueError, match="max_leaf_size|leaf"):
        kestrel.build_accel(kestrel.Scene.from_arrays(vertices, indices), max_leaf_size=0)
    # A Python list is fine (converted).
    hits = kestrel.trace(accel, rays.tolist())
    assert len(hits["t"]) == 10


def test_nan_and_empty_rays_miss(soup):
    vertices, indices, _ = soup
    accel = kestrel.build_accel(kestrel.Scene.from_arrays(vertices, indices))
    rays = random_rays(seed=14, count=4)
    rays[0, 3] = np.nan
    rays[1, 3:6] = 0
    hits = kestrel.trace(accel, rays)
    assert hits["prim_id"][0] == kestrel.invalid_id and hits["prim_id"][1] == kestrel.invalid_id
    empty = kestrel.trace(accel, np.empty((0, 8), dtype=np.float32))
    assert len(empty["t"]) == 0
