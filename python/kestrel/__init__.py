"""kestrel from Python: numpy in, numpy out.

CPU ray tracing -- BVH builds, wide-BVH SIMD traversal with exact hits, two-level scenes, a
path tracer with every AOV, denoisers, temporal upsamplers and the real-time loop -- over
numpy arrays. Rays are (N, 8) float32 arrays in the `.rays` record layout (org, dir, tmin,
tmax) and are traced in place; images are float32 (H, W, C) arrays, rows top to bottom.

    import kestrel, numpy as np
    scene = kestrel.load_scene("builtin:cornell_box")
    accel = kestrel.build_accel(scene)
    hits = kestrel.trace(accel, rays)            # dict of t, prim_id, u, v
    frame = kestrel.Renderer(scene).render(kestrel.view(scene), spp=16, res=(320, 180))

Errors: TypeError for a wrong dtype, ValueError for a wrong shape or value (and malformed
files), OSError / FileNotFoundError for files that cannot be opened or written.
"""
import os as _os

# An installed package carries the trained weights (setup.py copies them beside the module).
_weights = _os.path.join(_os.path.dirname(__file__), "weights")
if _os.path.isdir(_weights):
    _os.environ.setdefault("KESTREL_WEIGHTS_DIR", _weights)

# oneDNN's OpenMP threads sleep between its parallel regions instead of spinning against
# kestrel's own threads (apps/common/openmp_env.h says why); libgomp reads this when it
# loads with the extension, so it is set first. A user's own setting is kept.
_os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

from ._kestrel import *  # noqa: F401,F403,E402
from ._kestrel import _last_inputs  # noqa: F401
from ._kestrel import (Accel, Camera, CameraPath, Denoiser, InstancedScene, Pipeline, Renderer, Scene,  # noqa: F401
                       Upscaler, aov_names, build_accel, builtin_scene_names, bvh_metrics, default_isa, denoise,
                       hardware_thread_count, hit_dtype, host_isa, instance_hit_dtype, invalid_id, isa_supported,
                       load_scene, occluded, read_exr, read_hits, read_image, read_pfm, read_rays, set_default_isa,
                       tonemap, trace, upscale, view, write_exr, write_hits, write_pfm, write_png, write_rays)

__version__ = "0.1.0"


def rays_array(origins, directions, tmin=0.0, tmax=float("inf")):
    """Packs origins (N, 3) and directions (N, 3) into an (N, 8) float32 rays array."""
    import numpy as np

    o = np.asarray(origins, dtype=np.float32)
    d = np.asarray(directions, dtype=np.float32)
    if o.ndim != 2 or o.shape[1] != 3:
        raise ValueError(f"origins: expected shape (N, 3), got {o.shape}")
    if d.shape != o.shape:
        raise ValueError(f"directions: expected shape {o.shape}, got {d.shape}")
    rays = np.empty((o.shape[0], 8), dtype=np.float32)
    rays[:, 0:3] = o
    rays[:, 3:6] = d
    rays[:, 6] = tmin
    rays[:, 7] = tmax
    return rays


def camera_rays(camera, res):
    """Pinhole rays through pixel centres, row by row (as `kestrel rays --kind primary`), (W*H, 8) float32."""
    import numpy as np

    w, h = res
    eye = np.array(camera.eye, dtype=np.float64)
    forward = np.array(camera.target, dtype=np.float64) - eye
    forward /= np.linalg.norm(forward)
    right = np.cross(forward, [0.0, 1.0, 0.0])
    if np.linalg.norm(right) < 1e-8:
        right = np.array([1.0, 0.0, 0.0])
    right /= np.linalg.norm(right)
    up = np.cross(right, forward)
    half_h = np.tan(np.radians(camera.vfov) / 2)
    half_w = half_h * w / h
    xs = ((np.arange(w) + 0.5) / w * 2 - 1) * half_w
    ys = (1 - (np.arange(h) + 0.5) / h * 2) * half_h
    px, py = np.meshgrid(xs, ys)
    d = forward[None, None, :] + px[..., None] * right + py[..., None] * up
    d = d.reshape(-1, 3)
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    return rays_array(np.broadcast_to(eye, d.shape), d)
