"""Builds the extension lidar2d._lidar2d with CMake (the project's own build, Release, without the
program, tests and benchmarks) and packages it with python/lidar2d/. The CMake tree goes to
LIDAR2D_PIP_BUILD_DIR, else setuptools' build_temp; ccache is used when installed."""
import os
import shutil
import subprocess
import sys

from setuptools import Extension, setup
from setuptools.command.build_ext import build_ext

ROOT = os.path.dirname(os.path.abspath(__file__))


class CMakeExtension(Extension):
    def __init__(self, name):
        super().__init__(name, sources=[])


class CMakeBuild(build_ext):
    def build_extension(self, ext):
        build_dir = os.path.abspath(os.environ.get("LIDAR2D_PIP_BUILD_DIR", os.path.join(self.build_temp, "cmake")))
        configure = ["cmake", "-S", ROOT, "-B", build_dir, "-DCMAKE_BUILD_TYPE=Release",
                     "-DLIDAR2D_BUILD_APPS=OFF", "-DLIDAR2D_BUILD_TESTS=OFF", "-DLIDAR2D_BUILD_BENCH=OFF",
                     "-DLIDAR2D_BUILD_PYTHON=ON", f"-DPython_EXECUTABLE={sys.executable}"]
        if shutil.which("ccache"):
            configure.append("-DCMAKE_CXX_COMPILER_LAUNCHER=ccache")
        subprocess.run(configure, check=True)
        jobs = os.environ.get("CMAKE_BUILD_PARALLEL_LEVEL", "2")
        subprocess.run(["cmake", "--build", build_dir, "--target", "_lidar2d", "-j", jobs], check=True)
        built = os.path.join(build_dir, "python", "lidar2d")
        so = next(f for f in os.listdir(built) if f.startswith("_lidar2d") and f.endswith(".so"))
        target = self.get_ext_fullpath(ext.name)
        os.makedirs(os.path.dirname(target), exist_ok=True)
        shutil.copyfile(os.path.join(built, so), target)


setup(
    packages=["lidar2d"],
    package_dir={"": "python"},
    package_data={"lidar2d": ["*.pyi", "py.typed"]},
    ext_modules=[CMakeExtension("lidar2d._lidar2d")],
    cmdclass={"build_ext": CMakeBuild},
    zip_safe=False,
)
