"""Scenes from numpy arrays and files, BVH metrics and two-level scenes from Python."""
import json
import math
import warnings

import numpy as np
import pytest

import kestrel
from conftest import bits, random_rays, triangle_soup, write_obj


def test_from_arrays_equals_the_loaded_obj(tmp_path):
    vertices, indices = triangle_soup(seed=21, count=500)
    write_obj(tmp_path / "soup.obj", vertices, indices)
    loaded = kestrel.load_scene(str(tmp_path / "soup.obj"))
    made = kestrel.Scene.from_arrays(vertices, indices, name="soup")
    assert loaded.mesh_names == made.mesh_names == ["soup"]
    assert np.array_equal(bits(loaded.vertices()), bits(made.vertices()))
    assert np.array_equal(loaded.indices(), made.indices())
    assert np.array_equal(loaded.material_ids(), made.material_ids())
    assert loaded.material_count == made.material_count == 1
    assert loaded.validation() == made.validation()
    rays = random_rays(seed=22, count=5000)
    a = kestrel.trace(kestrel.build_accel(loaded), rays)
    b = kestrel.trace(kestrel.build_accel(made), rays)
    assert np.array_equal(bits(a["t"]), bits(b["t"])) and np.array_equal(a["prim_id"], b["prim_id"])


def test_from_arrays_checks_its_arrays():
    vertices, indices = triangle_soup(seed=23, count=10)
    with pytest.raises(TypeError, match="vertices: expected dtype float32"):
        kestrel.Scene.from_arrays(vertices.astype(np.float64), indices)
    with pytest.raises(TypeError, match="indices: expected dtype uint32"):
        kestrel.Scene.from_arrays(vertices, indices.astype(np.int64))
    with pytest.raises(ValueError, match=r"vertices: expected shape \(N, 3\)"):
        kestrel.Scene.from_arrays(vertices[:, :2].copy(), indices)
    bad = indices.copy()
    bad[4, 1] = 30
    with pytest.raises(ValueError, match="indices: row 4 refers to vertex 30, but there are 30 vertices"):
        kestrel.Scene.from_arrays(vertices, bad)
    with pytest.raises(ValueError, match="normals: expected shape"):
        kestrel.Scene.from_arrays(vertices, indices, normals=np.zeros((3, 3), np.float32))
    with pytest.raises(ValueError, match="nan_policy"):
        kestrel.Scene.from_arrays(vertices, indices, nan_policy="sometimes")


def test_nan_vertices_follow_the_policy():
    vertices, indices = triangle_soup(seed=24, count=10)
    vertices[0, 0] = np.nan
    vertices[7, 2] = np.inf
    with pytest.warns(RuntimeWarning, match="2 of 30 vertices have a NaN or Inf coordinate"):
        scene = kestrel.Scene.from_arrays(vertices, indices)
    assert scene.validation()["nonfinite"] == 2 and scene.validation()["valid"] == 8
    with pytest.raises(ValueError, match="NaN or Inf"):
        kestrel.Scene.from_arrays(vertices, indices, nan_policy="raise")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        kestrel.Scene.from_arrays(vertices, indices, nan_policy="ignore")
    # The skipped triangles are never hit.
    accel = kestrel.build_accel(scene)
    hits = kestrel.trace(accel, random_rays(seed=25, count=20000))
    assert accel.prim_count == 8
    assert not np.isin(hits["prim_id"], [0, 2]).any()


def test_bad_files_raise_oserror_or_valueerror(tmp_path):
    with pytest.raises(FileNotFoundError, match="missing.obj"):
        kestrel.load_scene(str(tmp_path / "missing.obj"))
    (tmp_path / "bad.gltf").write_text("{ this is not json")
    with pytest.raises(ValueError, match="bad.gltf"):
        kestrel.load_scene(str(tmp_path / "bad.gltf"))
    with pytest.raises(ValueError, match="builtin"):
        kestrel.load_scene("builtin:no_such_scene")


def test_bvh_metrics_equal_the_cli(cli):
    for builder in ("binned", "sweep", "lbvh", "spatial"):
        expected = json.loads(cli("bvh", "builtin:cornell_box", "--builder", builder, "--json", "--repeat", 1))
        got = kestrel.bvh_metrics(kestrel.load_scene("builtin:cornell_box"), builder=builder)
        for key in ("builder", "triangles", "valid_triangles", "nodes", "inner_nodes", "leaves", "max_depth", "valid"):
            assert got[key] == expected[key], (builder, key)
        for key in ("sah_cost", "sah_cost_unit", "mean_leaf_depth", "bytes_per_prim"):
            assert got[key] == pytest.approx(expected[key], abs=1e-3), (builder, key)
        assert got["leaf_size_histogram"][1:] == expected["leaf_size_histogram"]


def rotation_y(degrees):
    c, s = math.cos(math.radians(degrees)), math.sin(math.radians(degrees))
    return np.array([[c, 0, s, 0], [0, 1, 0, 0], [-s, 0, c, 0], [0, 0, 0, 1]])


def test_instances_trace_like_their_flattened_scene():
    vertices, indices = triangle_soup(seed=26, count=1500)
    scene = kestrel.InstancedScene()
    mesh = scene.add_mesh(vertices, indices)
    a = scene.add_instance(mesh)  # identity
    t = rotation_y(30)
    t[:3, 3] = (1.5, 0.2, -0.3)
    b = scene.add_instance(mesh, t)  # (4, 4)
    c = scene.add_instance(mesh, (np.eye(4) * 0.5)[:3] + np.array([[0, 0, 0, -1.0], [0, 0, 0, 0], [0, 0, 0, 0]]))
    stats = scene.commit()
    assert stats["instances"] == 3 and scene.instance_count == 3
    np.testing.assert_allclose(scene.transform(b), t[:3].astype(np.float32))
    rays = random_rays(seed=27, count=20000, lo=-1.5, hi=2.5)
    hits = scene.trace(rays)
    flat = scene.flatten()  # one mesh per instance, instance-id order
    flat_hits = kestrel.trace(kestrel.build_accel(flat), rays)
    hit = hits["instance_id"] != kestrel.invalid_id
    assert hit.sum() > 500
    assert np.array_equal(hit, flat_hits["prim_id"] != kestrel.invalid_id)
    tri = len(indices)
    assert np.array_equal(flat_hits["prim_id"][hit] // tri, hits["instance_id"][hit])
    assert np.array_equal(flat_hits["prim_id"][hit] % tri, hits["prim_id"][hit])
    np.testing.assert_allclose(hits["t"][hit], flat_hits["t"][hit], rtol=1e-4)
    occ = scene.occluded(rays)
    assert np.array_equal(occ, hit)
    assert {a, b, c} == {0, 1, 2}


def test_instance_transforms_are_checked():
    vertices, indices = triangle_soup(seed=28, count=5)
    scene = kestrel.InstancedScene()
    mesh = scene.add_mesh(vertices, indices)
    with pytest.raises(ValueError, match=r"transform: expected shape \(3, 4\) or \(4, 4\)"):
        scene.add_instance(mesh, np.eye(3))
    with pytest.raises(ValueError, match="last row"):
        scene.add_instance(mesh, np.ones((4, 4)))
    with pytest.raises(ValueError, match="transform"):
        scene.add_instance(mesh, np.zeros((3, 4)))  # singular
    nan = np.eye(4)
    nan[0, 3] = np.nan
    with pytest.raises(ValueError, match="transform"):
        scene.add_instance(mesh, nan)
    with pytest.raises(ValueError):
        scene.add_instance(mesh + 5)


def test_gltf_instances_animate(tmp_path):
    import pathlib

    box = pathlib.Path(__file__).resolve().parents[3] / "shared" / "scenes" / "gltf_box_animated" / "BoxAnimated.gltf"
    if not box.exists():
        pytest.skip("../shared/scenes/gltf_box_animated is not here")
    scene = kestrel.InstancedScene.load_gltf(str(box))
    scene.commit()
    assert scene.duration > 0 and scene.instance_count > 0
    at_rest = scene.flatten()
    scene.set_time(scene.duration / 2)
    scene.commit()
    posed = scene.flatten()
    moved = [not np.array_equal(at_rest.vertices(i), posed.vertices(i)) for i in range(posed.mesh_count)]
    assert any(moved)
    with pytest.raises(ValueError, match="not loaded from a glTF"):
        kestrel.InstancedScene().set_time(0.5)
