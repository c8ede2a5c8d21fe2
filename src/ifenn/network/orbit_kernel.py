"""The compiled orbit layer and pixel operator (orbit_kernel.cpp): built at first use, loaded
with ctypes.

``load()`` returns the library, or None where it cannot be had (no C++ compiler, a failed
build, or ``IFENN_KERNEL=0`` in the environment); callers then use the torch path of
:mod:`ifenn.network.orbit`, which computes the same thing more slowly. dolfinx compiles its forms
with the same compiler, so wherever the finite-element side runs the kernel builds too.

The library is built with ``-O3 -march=native`` into ``$IFENN_KERNEL_CACHE`` (default
``~/.cache/ifenn``) under a name that hashes the source, the flags, the compiler and the
CPU's instruction sets, so a changed source or another machine sharing the directory gets
its own build. A build writes a temporary file and renames it: concurrent jobs that build
at once each end with a complete library.
"""

from __future__ import annotations

import ctypes
import functools
import hashlib
import os
import shutil
import subprocess
import warnings
from pathlib import Path

SOURCE = Path(__file__).with_name("orbit_kernel.cpp")
FLAGS = ("-O3", "-march=native", "-std=c++17", "-shared", "-fPIC")
VERSION = 8
#: floats after the last pixel of every buffer handed to the kernel (a chunk reads past a run's end)
SLACK = 64
ACTIVATIONS = {"none": 0, "tanh": 1, "sigmoid": 2}


def _cpu_flags() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith(("flags", "Features")):
                return line
    except OSError:
        pass
    import platform

    return platform.processor() or platform.machine()


def _build(compiler: str) -> Path:
    version = subprocess.run([compiler, "--version"], capture_output=True, text=True, check=True).stdout
    key = hashlib.sha256("\n".join([SOURCE.read_text(), " ".join(FLAGS), version, _cpu_flags()]).encode()).hexdigest()[:16]
    cache = Path(os.environ.get("IFENN_KERNEL_CACHE") or Path.home() / ".cache" / "ifenn")
    target = cache / f"orbit_kernel-{key}.so"
    if not target.exists():
        cache.mkdir(parents=True, exist_ok=True)
        partial = cache / f".{target.name}.{os.getpid()}.partial"
        try:
            subprocess.run([compiler, *FLAGS, "-o", str(partial), str(SOURCE)], capture_output=True, text=True, check=True)
            os.replace(partial, target)
        finally:
            partial.unlink(missing_ok=True)
    return target


@functools.cache
def load() -> ctypes.CDLL | None:
    """The compiled kernel, or None (with a warning saying why, unless disabled on purpose)."""
    if os.environ.get("IFENN_KERNEL", "1") == "0":
        return None
    compiler = shutil.which(os.environ.get("CXX", "g++")) or shutil.which("c++")
    if compiler is None:
        warnings.warn("no C++ compiler (g++): the PICNN runs on the slower torch orbit path", stacklevel=2)
        return None
    try:
        lib = ctypes.CDLL(str(_build(compiler)))
    except (OSError, subprocess.CalledProcessError) as error:
        detail = getattr(error, "stderr", "") or str(error)
        warnings.warn(f"building {SOURCE.name} failed, the PICNN runs on the slower torch orbit path:\n{detail}", stacklevel=2)
        return None
    pointer, integer = ctypes.c_void_p, ctypes.c_int
    lib.ifenn_orbit_layer.argtypes = [pointer, integer, integer, integer, integer, pointer, integer, pointer, pointer,
                                      integer, integer, integer, integer, integer]
    lib.ifenn_orbit_layer.restype = integer
    lib.ifenn_dilate.argtypes = [pointer, pointer, pointer, integer, integer, integer]
    lib.ifenn_dilate.restype = None
    lib.ifenn_pixel_residual.argtypes = [pointer, pointer, pointer, integer, integer, integer, integer, integer, integer,
                                         ctypes.c_double, ctypes.c_double, integer, integer]
    lib.ifenn_pixel_residual.restype = None
    lib.ifenn_pixel_mg_pcg.argtypes = [pointer, pointer, pointer, integer, integer, ctypes.c_double, pointer, ctypes.c_double, integer,
                                       pointer, integer, pointer, pointer, pointer, pointer]
    lib.ifenn_pixel_mg_pcg.restype = integer
    lib.ifenn_kernel_version.restype = integer
    if lib.ifenn_kernel_version() != VERSION:
        warnings.warn(f"{SOURCE.name}: version mismatch, using the torch orbit path", stacklevel=2)
        return None
    return lib


def supports(kernel_size: int) -> bool:
    """Kernel radii the library was instantiated for."""
    return kernel_size // 2 in (1, 2, 3)
