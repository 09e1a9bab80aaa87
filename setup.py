"""Builds the Python module `kestrel` with CMake for `pip install --no-build-isolation .`.

The extension is the CMake target kestrel_python, built in $KESTREL_BUILD_DIR (default
build/pip; point it at an existing build such as build/release to reuse it); the package's
Python files and the trained weights are copied beside it, and the package points
KESTREL_WEIGHTS_DIR at its own copy of the weights.
"""
import os
import pathlib
import shutil
import subprocess
import sys

from setuptools import Extension, setup
from setuptools.command.build_ext import build_ext

ROOT = pathlib.Path(__file__).resolve().parent


class CMakeBuild(build_ext):
    def build_extension(self, ext):
        build_dir = pathlib.Path(os.environ.get("KESTREL_BUILD_DIR", ROOT / "build" / "pip")).resolve()
        if not (build_dir / "CMakeCache.txt").exists():
            configure = ["cmake", "-S", str(ROOT), "-B", str(build_dir), "-DCMAKE_BUILD_TYPE=Release",
                         f"-DPython_EXECUTABLE={sys.executable}", "-DKESTREL_BUILD_TESTS=OFF"]
            if shutil.which("ninja"):
                configure += ["-G", "Ninja"]
            if shutil.which("ccache"):
                configure.append("-DCMAKE_CXX_COMPILER_LAUNCHER=ccache")
            subprocess.check_call(configure)
        subprocess.check_call(["cmake", "--build", str(build_dir), "--target", "kestrel_python", "-j",
                               str(os.cpu_count() or 2)])
        built = build_dir / "python" / "kestrel"
        libraries = sorted(built.glob("_kestrel*.so"))
        if not libraries:
            raise RuntimeError(f"{built}: the CMake build made no _kestrel extension (is pybind11-dev installed?)")
        dest = pathlib.Path(self.get_ext_fullpath(ext.name))
        dest.parent.mkdir(parents=True, exist_ok=True)
        shutil.copy2(libraries[0], dest)
        weights = dest.parent / "weights"
        weights.mkdir(exist_ok=True)
        for f in (ROOT / "weights").glob("*.kdw"):
            shutil.copy2(f, weights / f.name)


setup(
    packages=["kestrel"],
    package_dir={"": "python"},
    package_data={"kestrel": ["__init__.pyi", "py.typed"]},
    ext_modules=[Extension("kestrel._kestrel", sources=[])],
    cmdclass={"build_ext": CMakeBuild},
    zip_safe=False,
)
