#!/usr/bin/env bash
# `pip install --no-build-isolation .` into a fresh virtual environment of Debian's python3
# (with its site packages: numpy, setuptools; nothing downloaded), reusing the given CMake
# build; then, from outside the source tree, import the installed package and use it.
#   pip_install.sh SOURCE_DIR BUILD_DIR WORK_DIR
set -euo pipefail
src=$1 build=$2 work=$3
python=${KESTREL_PYTHON:-/usr/bin/python3}
rm -rf "$work"
mkdir -p "$work"
"$python" -m venv --system-site-packages "$work/venv"
KESTREL_BUILD_DIR="$build" "$work/venv/bin/python" -m pip install --no-build-isolation --no-index --no-deps -q "$src"
cd "$work"
env -u PYTHONPATH -u KESTREL_WEIGHTS_DIR "$work/venv/bin/python" - <<'PY'
import os
import numpy as np
import kestrel

where = os.path.dirname(kestrel.__file__)
assert where.startswith(os.path.realpath(os.environ.get("VIRTUAL_ENV", "")) or os.getcwd()), where
assert os.path.isfile(os.path.join(where, "__init__.pyi")) and os.path.isfile(os.path.join(where, "py.typed"))
assert os.environ["KESTREL_WEIGHTS_DIR"] == os.path.join(where, "weights"), os.environ["KESTREL_WEIGHTS_DIR"]
scene = kestrel.load_scene("builtin:cornell_box")
hits = kestrel.trace(kestrel.build_accel(scene), kestrel.camera_rays(kestrel.view(scene), (32, 32)))
assert np.isfinite(hits["t"]).sum() > 500
frame = kestrel.Renderer(scene).render(kestrel.view(scene), spp=1, res=(32, 24))
out = kestrel.denoise(frame["color"], albedo=frame["albedo"], normal=frame["normal"])  # the packaged weights
assert out.shape == (24, 32, 3) and np.isfinite(out).all()
print("installed kestrel at", where, "works")
PY
