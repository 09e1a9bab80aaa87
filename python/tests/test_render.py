"""Rendering, denoising, upsampling, the real-time loop and image files from Python, against
the CLI's outputs for the same settings."""
import numpy as np
import pytest

import kestrel
from conftest import bits

RES = (48, 32)


@pytest.fixture(scope="module")
def cornell():
    return kestrel.load_scene("builtin:cornell_box")


@pytest.fixture(scope="module")
def frame(cornell):
    return kestrel.Renderer(cornell).render(kestrel.view(cornell), spp=4, res=RES, seed=3)


def test_aovs_equal_the_cli_pfms(cli, frame, tmp_path):
    cli("render", "builtin:cornell_box", "--res", f"{RES[0]}x{RES[1]}", "--spp", 4, "--seed", 3, "--quiet",
        "-o", tmp_path / "f.exr", "--pfm", tmp_path / "pfm")
    assert sorted(frame) == sorted(kestrel.aov_names)
    for name in kestrel.aov_names:
        pfm = kestrel.read_pfm(str(tmp_path / "pfm" / f"{name}.pfm"))
        mine = frame[name]
        assert mine.dtype == np.float32 and mine.shape[:2] == (RES[1], RES[0])
        assert np.array_equal(bits(mine), bits(pfm[..., : mine.shape[2]])), name
    exr = kestrel.read_exr(str(tmp_path / "f.exr"))
    assert np.array_equal(bits(exr["color"]), bits(frame["color"]))
    assert np.array_equal(bits(exr["normal"]), bits(frame["normal"]))
    assert frame["color"].mean() > 0.01  # it is lit


def test_renderer_over_an_instanced_scene(cornell, frame):
    # One identity instance of the box's mesh with its materials: the same bits as the Scene.
    two = kestrel.InstancedScene()
    mesh = two.add_scene_mesh(cornell, 0)
    inst = two.add_instance(mesh)
    two.set_materials_from(cornell)
    two.commit()
    r = kestrel.Renderer(two)
    same = r.render(kestrel.view(cornell), spp=4, res=RES, seed=3)
    for name in kestrel.aov_names:
        assert np.array_equal(bits(same[name]), bits(frame[name])), name
    # The renderer references the scene (kept alive) and sees each commit: moved, the image
    # changes and the motion vectors point back to where the surface was.
    del two
    import gc
    gc.collect()
    again = r.render(kestrel.view(cornell), spp=4, res=RES, seed=3)
    assert np.array_equal(bits(again["color"]), bits(frame["color"]))


def test_renderer_sees_commits_of_an_instanced_scene(cornell):
    two = kestrel.InstancedScene()
    inst = two.add_instance(two.add_scene_mesh(cornell, 0))
    two.set_materials_from(cornell)
    two.commit()
    r = kestrel.Renderer(two)
    cam = kestrel.view(cornell)
    before = r.render(cam, res=RES, jitter=False)
    t = np.eye(4, dtype=np.float32)
    t[0, 3] = 0.05  # move the whole box along +x
    two.set_transform(inst, t)
    two.commit()
    after = r.render(cam, res=RES, jitter=False)
    assert not np.array_equal(before["depth"], after["depth"])
    moving = np.abs(after["motion"][..., 0]) > 1e-3
    assert moving.mean() > 0.5  # the surface seen moved, all of it one way on the screen
    assert abs(np.sign(after["motion"][..., 0][moving]).mean()) > 0.9
    # and the first render (no earlier commit seen) had no object motion at all
    assert np.abs(before["motion"]).max() == 0


def test_aovs_are_arrays_over_the_frame(frame):
    for name in kestrel.aov_names:
        assert not frame[name].flags.owndata  # numpy views of the frame's pixels, not copies
        assert frame[name].flags.c_contiguous


def test_render_is_the_same_for_any_thread_count(cornell):
    r = kestrel.Renderer(cornell)
    a = r.render(kestrel.view(cornell), spp=2, res=RES, seed=9, threads=1)
    b = r.render(kestrel.view(cornell), spp=2, res=RES, seed=9, threads=2)
    for name in kestrel.aov_names:
        assert np.array_equal(bits(a[name]), bits(b[name])), name
    assert r.last_stats["passes"] == 2


def test_translucent_material_is_seen_by_alpha_of_the_rays():
    # A red quad with alpha 0.25 over a grey floor, seen straight down: the albedo AOV mixes
    # them as 0.25 : 0.75; alpha outside [0, 1] is refused.
    scene = kestrel.Scene()
    floor = scene.add_material("floor", base_color=(0.5, 0.5, 0.5))
    glass = scene.add_material("glass", base_color=(0.9, 0.1, 0.1), alpha=0.25)
    quad = np.array([[-1, 0, -1], [1, 0, -1], [1, 0, 1], [-1, 0, 1]], np.float32)
    tris = np.array([[0, 2, 1], [0, 3, 2]], np.uint32)
    scene.add_mesh(quad * 20, tris, material=floor)
    scene.add_mesh(quad + np.float32([0, 1, 0]), tris, material=glass)
    frame = kestrel.Renderer(scene).render(kestrel.Camera((0, 8, 0.01), (0, 0, 0), 10), spp=64, res=(8, 8))
    assert frame["albedo"][..., 0].mean() == pytest.approx(0.25 * 0.9 + 0.75 * 0.5, abs=0.02)
    with pytest.raises(ValueError, match="alpha"):
        scene.add_material("bad", alpha=1.5)


def test_glass_pane_passes_its_tint_and_reflects_fresnel():
    # A smooth thin glass pane seen head-on in a uniform environment of 1: F0 = 0.04 of the
    # environment behind the camera plus 0.96 of the tint; a bad ior or transmission is refused.
    scene = kestrel.Scene()
    tint = (0.2, 0.5, 0.9)
    pane = scene.add_material("pane", base_color=tint, roughness=0.0, specular=1.0,
                              transmission=1.0, ior=1.5, thin_walled=True)
    quad = np.array([[-5, -5, 0], [5, -5, 0], [5, 5, 0], [-5, 5, 0]], np.float32)
    scene.add_mesh(quad, np.array([[0, 1, 2], [0, 2, 3]], np.uint32), material=pane)
    r = kestrel.Renderer(scene, environment="constant:1,1,1")
    frame = r.render(kestrel.Camera((0, 0, -3), (0, 0, 0), 1), spp=1024, res=(2, 2))
    for k in range(3):
        assert frame["color"][..., k].mean() == pytest.approx(0.04 + 0.96 * tint[k], abs=0.02)
    with pytest.raises(ValueError, match="ior"):
        scene.add_material("bad", transmission=1.0, ior=0.5)
    with pytest.raises(ValueError, match="transmission"):
        scene.add_material("bad", transmission=2.0)


def test_vertex_colors_multiply_the_base_colour():
    # A quad whose four corners are one colour, seen straight down: the albedo AOV is the
    # base colour times it; colours outside [0, 1] or of the wrong shape are refused.
    scene = kestrel.Scene()
    grey = scene.add_material("grey", base_color=(0.5, 0.5, 0.5))
    quad = np.array([[-1, 0, -1], [1, 0, -1], [1, 0, 1], [-1, 0, 1]], np.float32)
    tris = np.array([[0, 2, 1], [0, 3, 2]], np.uint32)
    colors = np.tile(np.float32([0.2, 0.6, 1.0]), (4, 1))
    scene.add_mesh(quad, tris, material=grey, colors=colors)
    frame = kestrel.Renderer(scene).render(kestrel.Camera((0, 8, 0.01), (0, 0, 0), 5), spp=1, res=(4, 4))
    assert frame["albedo"][..., :3].mean(axis=(0, 1)) == pytest.approx([0.1, 0.3, 0.5], abs=1e-4)
    with pytest.raises(ValueError, match="colors"):
        scene.add_mesh(quad, tris, colors=colors * 2)
    with pytest.raises(ValueError, match="colors"):
        scene.add_mesh(quad, tris, colors=colors[:3])


def test_render_arguments_are_checked(cornell):
    r = kestrel.Renderer(cornell)
    cam = kestrel.view(cornell)
    with pytest.raises(ValueError, match="res"):
        r.render(cam, res=(0, 10))
    with pytest.raises(TypeError, match="res"):
        r.render(cam, res="big")
    with pytest.raises(ValueError, match="spp"):
        r.render(cam, spp=0, res=RES)
    with pytest.raises(ValueError, match="eye and target"):
        kestrel.Camera(eye=(0, 0, 0), target=(0, 0, 0))
    with pytest.raises(ValueError, match="no view named 'nowhere'"):
        kestrel.view(cornell, "nowhere")
    with pytest.raises((ValueError, OSError)):
        kestrel.Renderer(cornell, environment="/no/such/sky.exr")


def test_denoise_equals_the_cli(cli, frame, tmp_path):
    for name in ("color", "albedo", "normal"):
        kestrel.write_pfm(str(tmp_path / f"{name}.pfm"), frame[name])
    for method in ("neural", "svgf", "atrous", "rae"):
        cli("denoise", "--hdr", tmp_path / "color.pfm", "--alb", tmp_path / "albedo.pfm", "--nrm",
            tmp_path / "normal.pfm", "-o", tmp_path / "out.pfm", "--method", method, "--quiet")
        expected = kestrel.read_pfm(str(tmp_path / "out.pfm"))
        got = kestrel.denoise(frame["color"], albedo=frame["albedo"], normal=frame["normal"], method=method)
        assert got.shape == (RES[1], RES[0], 3)
        assert np.array_equal(bits(got), bits(expected)), method
    # fp32 where bf16 is the default: the CLI's --fp32
    for method in ("neural", "rae"):
        cli("denoise", "--hdr", tmp_path / "color.pfm", "--alb", tmp_path / "albedo.pfm", "--nrm",
            tmp_path / "normal.pfm", "-o", tmp_path / "out.pfm", "--method", method, "--fp32", "--quiet")
        expected = kestrel.read_pfm(str(tmp_path / "out.pfm"))
        d = kestrel.Denoiser(method, bf16=False)
        assert not d.uses_bf16
        got = d.denoise(frame["color"], albedo=frame["albedo"], normal=frame["normal"])
        assert np.array_equal(bits(got), bits(expected)), method


def test_denoise_inputs_are_checked(frame, tmp_path):
    color = frame["color"]
    out = np.zeros_like(color)
    result = kestrel.denoise(color, albedo=frame["albedo"], out=out)
    assert np.shares_memory(result, out) and out.any()
    with pytest.raises(ValueError, match="albedo: size 24x32 differs from color's 48x32"):
        kestrel.denoise(color, albedo=np.ascontiguousarray(frame["albedo"][:, :24]))
    with pytest.raises(ValueError, match="color: expected 3 channels"):
        kestrel.denoise(frame["depth"])
    with pytest.raises(TypeError, match="color: expected dtype float32"):
        kestrel.denoise(color.astype(np.float16))
    nan = color.copy()
    nan[3, 4, 1] = np.nan
    assert np.isfinite(kestrel.denoise(nan)).all()  # NaN read as 0 by default
    with pytest.raises(ValueError, match=r"color: non-finite value at pixel \(4, 3\)"):
        kestrel.denoise(nan, nan_policy="raise")
    with pytest.raises(ValueError, match="method"):
        kestrel.denoise(color, method="oidn")
    (tmp_path / "bad.kdw").write_bytes(b"KDW1 definitely not weights")
    with pytest.raises(ValueError, match="bad.kdw"):
        kestrel.denoise(color, weights=str(tmp_path / "bad.kdw"))
    with pytest.raises(OSError, match="missing.kdw"):
        kestrel.Denoiser(weights=str(tmp_path / "missing.kdw"))
    with pytest.raises(ValueError, match="out: expected shape"):
        kestrel.denoise(color, out=np.zeros((2, 2, 3), np.float32))


def test_denoiser_sequence_carries_state(cornell):
    r = kestrel.Renderer(cornell)
    cam = kestrel.view(cornell)
    d = kestrel.Denoiser("neural")
    outs = []
    for i in range(3):
        f = r.render(cam, spp=1, res=RES, seed=0, frame=i)
        outs.append(d.denoise(f["color"], albedo=f["albedo"], normal=f["normal"], depth=f["depth"],
                              roughness=f["roughness"], motion=f["motion"]))
    fresh = kestrel.Denoiser("neural").denoise(f["color"], albedo=f["albedo"], normal=f["normal"], depth=f["depth"],
                                               roughness=f["roughness"], motion=f["motion"])
    assert not np.array_equal(outs[-1], fresh)  # the history changed the third frame
    assert d.parameter_count > 0


def test_upscale(frame):
    up = kestrel.upscale(frame["color"], factor=2, method="bicubic")
    assert up.shape == (2 * RES[1], 2 * RES[0], 3)
    u = kestrel.Upscaler("neural", factor=4)
    big = u.upscale(frame["color"], depth=frame["depth"], motion=frame["motion"], jitter=(0.5, 0.5))
    assert big.shape == (4 * RES[1], 4 * RES[0], 3) and np.isfinite(big).all()
    # bf16 convolutions (the default where the CPU has them) or fp32: nearly the same frame
    u32 = kestrel.Upscaler("neural", factor=4, bf16=False)
    assert not u32.uses_bf16
    big32 = u32.upscale(frame["color"], depth=frame["depth"], motion=frame["motion"], jitter=(0.5, 0.5))
    assert np.allclose(big, big32, rtol=1e-2, atol=1e-3)
    with pytest.raises(ValueError, match="factor: must be 2 or 4"):
        kestrel.upscale(frame["color"], factor=3)
    with pytest.raises(ValueError, match="depth: size"):
        kestrel.upscale(frame["color"], depth=np.zeros((4, 4), np.float32))


@pytest.mark.parametrize("method", ["nsrr-rt", "nsrr"])
def test_upscale_nsrr_family(frame, method):
    u = kestrel.Upscaler(method, factor=2)
    assert u.method == method and u.parameter_count > 0
    for t in range(3):  # a window of frames: the first has no previous ones
        big = u.upscale(frame["color"], depth=frame["depth"], motion=frame["motion"], jitter=(0.5, 0.5))
        assert big.shape == (2 * RES[1], 2 * RES[0], 3) and np.isfinite(big).all()
    with pytest.raises(ValueError, match="depth"):  # the family needs depth and motion
        u.upscale(frame["color"], motion=frame["motion"])


def test_pipeline_steps_frame_by_frame(cornell):
    p = kestrel.Pipeline("builtin:cornell_box", res=(96, 64), factor=2)
    cam = kestrel.view(cornell)
    f0 = p.frame(cam, 0.0)
    f1 = p.frame(cam, 1 / 30)
    assert f1["index"] == f0["index"] + 1
    assert f1["noisy"].shape == (32, 48, 3) and f1["upscaled"].shape == (64, 96, 3)
    assert f1["rgb8"].dtype == np.uint8 and f1["rgb8"].shape == (64, 96, 3) and f1["rgb8"].any()
    assert set(f1["times"]) >= {"render", "denoise", "upscale", "tonemap", "total"}
    with pytest.raises(ValueError, match="denoiser"):
        kestrel.Pipeline("builtin:cornell_box", denoiser="magic")
    with pytest.raises(FileNotFoundError):
        kestrel.Pipeline("/no/such/scene.obj")


def test_image_files_round_trip(tmp_path):
    rng = np.random.default_rng(1)
    img = rng.random((5, 7, 3), dtype=np.float32)
    kestrel.write_pfm(str(tmp_path / "a.pfm"), img)
    assert np.array_equal(kestrel.read_pfm(str(tmp_path / "a.pfm")), img)
    depth = rng.random((5, 7), dtype=np.float32)
    kestrel.write_exr(str(tmp_path / "a.exr"), {"color": img, "depth": depth})
    layers = kestrel.read_exr(str(tmp_path / "a.exr"))
    assert np.array_equal(layers["color"], img) and np.array_equal(layers["depth"][..., 0], depth)
    with pytest.raises(ValueError, match="differs"):
        kestrel.write_exr(str(tmp_path / "b.exr"), {"color": img, "depth": depth[:4]})
    with pytest.raises(OSError):
        kestrel.write_pfm(str(tmp_path / "no" / "such" / "dir" / "a.pfm"), img)
    rgb = kestrel.tonemap(img)
    assert rgb.dtype == np.uint8 and rgb.shape == (5, 7, 3)
    kestrel.write_png(str(tmp_path / "a.png"), rgb)
    back = kestrel.read_image(str(tmp_path / "a.png"))
    assert back.shape == (5, 7, 3)
    # Every byte survives the PNG (zlib-deflated) round trip: read_image's sRGB decode of it.
    noise = rng.integers(0, 256, size=(53, 37, 3), dtype=np.uint8)
    kestrel.write_png(str(tmp_path / "n.png"), noise)
    c = noise.astype(np.float64) / 255
    decoded = np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)
    assert np.allclose(kestrel.read_image(str(tmp_path / "n.png")), decoded, atol=1e-5, rtol=0)
    with pytest.raises(ValueError, match="a.pfm|truncated|PFM"):
        (tmp_path / "t.pfm").write_bytes(b"PF\n7 5\n-1\n" + b"\0" * 10)
        kestrel.read_pfm(str(tmp_path / "t.pfm"))


def test_sun_and_sky(cornell):
    dark = kestrel.Renderer(cornell, environment="none")
    sunny = kestrel.Renderer(cornell, environment="none", sun="30,60,20")
    assert sunny.light_count == dark.light_count + 1
    cam = kestrel.view(cornell)
    a = dark.render(cam, res=RES, spp=2)["color"]
    b = sunny.render(cam, res=RES, spp=2)["color"]
    assert b.mean() >= a.mean()
    sky = kestrel.Renderer(cornell, sky=True).render(cam, res=RES, spp=2)["color"]
    assert np.isfinite(sky).all() and sky.mean() > 0
    with pytest.raises(ValueError, match="--sun"):
        kestrel.Renderer(cornell, sun="0,120")
    loop = kestrel.Pipeline("builtin:cornell_box", res=(32, 24), factor=1, denoiser=None, sun="0,45", auto_exposure=True)
    f = loop.frame(cam)
    assert f["exposure"] != 0.0 and f["rgb8"].shape == (24, 32, 3)


def test_radiance_cache_matches_the_cli(cli, tmp_path, cornell):
    """The radiance cache from Python: the CLI's bits (its later passes read what the earlier
    ones learnt), fewer rays than full paths; the loop takes it too."""
    cam = kestrel.view(cornell)
    r = kestrel.Renderer(cornell)
    mine = r.render(cam, res=RES, spp=4, seed=3, max_depth=5, radiance_cache=True)["color"]
    def rays():
        st = r.last_stats
        return st["camera_rays"] + st["bounce_rays"] + st["shadow_rays"]
    cached_rays = rays()
    r.render(cam, res=RES, spp=4, seed=3, max_depth=5)
    assert cached_rays < rays()
    steps = r.last_stats["steps"]  # the wall time by step: within the render's
    assert steps["shade_first"] > 0 and steps["trace_bounces"] > 0
    assert 0 < sum(steps.values()) <= r.last_stats["ms"] + 1e-6
    cli("render", "builtin:cornell_box", "--res", f"{RES[0]}x{RES[1]}", "--spp", 4, "--seed", 3,
        "--max-depth", 5, "--radiance-cache", "--quiet", "-o", tmp_path / "f.exr",
        "--pfm", tmp_path / "pfm")
    pfm = kestrel.read_pfm(str(tmp_path / "pfm" / "color.pfm"))
    assert np.array_equal(bits(mine), bits(pfm[..., :3]))
    for cache in (True, False):
        loop = kestrel.Pipeline("builtin:cornell_box", res=(32, 24), factor=1, denoiser=None,
                                radiance_cache=cache)
        assert np.isfinite(loop.frame(cam)["rgb8"]).all()


def test_indirect_rate_matches_the_cli(cli, tmp_path, cornell):
    """A quarter of the first bounces from Python: the CLI's bits, fewer bounce rays; a rate
    other than 1, 0.5 or 0.25 is an error."""
    cam = kestrel.view(cornell)
    r = kestrel.Renderer(cornell)
    r.render(cam, res=RES, spp=4, seed=5)
    full = r.last_stats["bounce_rays"]
    mine = r.render(cam, res=RES, spp=4, seed=5, indirect_rate=0.25)["color"]
    assert r.last_stats["bounce_rays"] < 0.5 * full
    cli("render", "builtin:cornell_box", "--res", f"{RES[0]}x{RES[1]}", "--spp", 4, "--seed", 5,
        "--indirect-rate", 0.25, "--quiet", "-o", tmp_path / "f.exr", "--pfm", tmp_path / "pfm")
    pfm = kestrel.read_pfm(str(tmp_path / "pfm" / "color.pfm"))
    assert np.array_equal(bits(mine), bits(pfm[..., :3]))
    with pytest.raises(Exception, match="indirect rate"):
        r.render(cam, res=RES, indirect_rate=0.3)
    loop = kestrel.Pipeline("builtin:cornell_box", res=(32, 24), factor=1, denoiser=None,
                            indirect_rate=0.5)
    assert np.isfinite(loop.frame(cam)["rgb8"]).all()
    with pytest.raises(Exception, match="indirect rate"):
        kestrel.Pipeline("builtin:cornell_box", res=(32, 24), indirect_rate=2)


def test_lights_file_matches_the_cli(cli, tmp_path, cornell):
    """A lights file from Python (Renderer and Pipeline), as `kestrel render --lights`: the
    CLI's bits, a brighter image; a bad light is an error naming the file and the light."""
    lights = tmp_path / "bulb.lights.json"
    lights.write_text('{"lights": [{"name": "bulb", "type": "point", '
                      '"position": [0.28, 0.3, 0.28], "intensity": 0.5}]}')
    cam = kestrel.view(cornell)
    plain = kestrel.Renderer(cornell)
    dark = plain.render(cam, res=RES, spp=4, seed=5)["color"]
    r = kestrel.Renderer(cornell, lights=lights)
    assert r.light_count == plain.light_count + 1
    mine = r.render(cam, res=RES, spp=4, seed=5)["color"]
    assert mine.mean() > 1.5 * dark.mean()
    cli("render", "builtin:cornell_box", "--res", f"{RES[0]}x{RES[1]}", "--spp", 4, "--seed", 5,
        "--lights", lights, "--quiet", "-o", tmp_path / "f.exr", "--pfm", tmp_path / "pfm")
    pfm = kestrel.read_pfm(str(tmp_path / "pfm" / "color.pfm"))
    assert np.array_equal(bits(mine), bits(pfm[..., :3]))
    loops = [kestrel.Pipeline("builtin:cornell_box", res=(32, 24), factor=1, denoiser=None,
                              **extra) for extra in ({}, {"lights": str(lights)})]
    dim, lit = (loop.frame(cam)["rgb8"].astype(np.float64).mean() for loop in loops)
    assert lit > dim
    bad = tmp_path / "bad.lights.json"
    bad.write_text('{"lights": [{"name": "dim", "type": "point", "intensity": -1}]}')
    for make in (lambda: kestrel.Renderer(cornell, lights=bad),
                 lambda: kestrel.Pipeline("builtin:cornell_box", res=(32, 24), lights=bad)):
        with pytest.raises(Exception, match="bad.lights.json") as e:
            make()
        assert "dim" in str(e.value)


def test_restir_matches_the_cli(cli, tmp_path):
    """ReSTIR DI from Python: the CLI's bits for the same settings; bad names are errors."""
    hall = kestrel.load_scene("builtin:lamp_hall")
    cam = kestrel.view(hall, "inside")
    mine = kestrel.Renderer(hall).render(cam, res=RES, spp=2, seed=4, light_sampling="tree",
                                         direct="restir")["color"]
    cli("render", "builtin:lamp_hall", "--view", "inside", "--res", f"{RES[0]}x{RES[1]}", "--spp", 2,
        "--seed", 4, "--light-sampling", "tree", "--direct", "restir", "--quiet",
        "-o", tmp_path / "f.exr", "--pfm", tmp_path / "pfm")
    pfm = kestrel.read_pfm(str(tmp_path / "pfm" / "color.pfm"))
    assert np.array_equal(bits(mine), bits(pfm[..., :3]))
    with pytest.raises(ValueError, match="direct"):
        kestrel.Renderer(hall).render(cam, res=RES, direct="ris")
    with pytest.raises(ValueError, match="light_sampling"):
        kestrel.Renderer(hall).render(cam, res=RES, light_sampling="bvh")
    for direct in ("restir", "auto"):
        loop = kestrel.Pipeline("builtin:lamp_hall", res=(32, 24), factor=1, denoiser=None,
                                light_sampling="tree", direct=direct)
        assert np.isfinite(loop.frame(cam)["rgb8"]).all()
    with pytest.raises(ValueError, match="direct"):
        kestrel.Pipeline("builtin:lamp_hall", res=(32, 24), factor=1, direct="ris")


def test_importing_kestrel_makes_openmp_threads_sleep():
    """oneDNN's OpenMP threads (rae, nsrr, nsrr-rt) sleep between its parallel regions unless
    the user chose otherwise: libgomp, loaded with the module, reports what it read."""
    import os
    import subprocess
    import sys

    def spin_count(policy):
        env = {k: v for k, v in os.environ.items() if k != "OMP_WAIT_POLICY"}
        env["OMP_DISPLAY_ENV"] = "verbose"
        if policy:
            env["OMP_WAIT_POLICY"] = policy
        out = subprocess.run([sys.executable, "-c", "import kestrel"], env=env, capture_output=True, text=True,
                             check=True).stderr
        return [line.split("=")[1].strip() for line in out.splitlines() if "GOMP_SPINCOUNT" in line]

    assert spin_count(None) == ["'0'"]
    assert spin_count("active") == ["'30000000000'"]
