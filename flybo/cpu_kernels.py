"""OpenBLAS's kernels and NumPy's SIMD loops, pinned so that a flight is the same on every
x86-64 machine.

NumPy and SciPy ship OpenBLAS built for many CPUs; at load it picks the kernels of the CPU it
finds (``Haswell`` on an AVX2 machine, ``SkylakeX`` on an Intel AVX-512 one, ...). The kernels
sum in different orders, so a dot product or a matrix product can differ in its last bits
between two machines, and a planner that compares such numbers can take another branch: the
same code, seed and preset flew four planners differently on an AVX-512 Intel machine and an
AMD one. Pinning the kernels to ``Haswell`` (AVX2 and FMA, every x86-64 CPU since 2013) makes
the machines agree. OpenBLAS reads the choice once, when it is loaded, from the environment
variable ``OPENBLAS_CORETYPE``, so `pin_blas_kernels` must run before NumPy is imported: the
``flybo`` package does it when it is imported, and so every command, worker and test process
that imports it first. The kernels in use are part of each run's reproducibility record
(`flybo.record`), and `blas_kernels_pinned` says whether they are the pinned ones.

NumPy, too, picks loops by CPU at load: on an AVX-512 machine its sine, cosine, arctangent and
others come from other implementations than on an AVX2 one, and differ in the last bits;
Classic flew differently on the two (`docs/notes/2026-12-numpy-simd.md`).
``NPY_DISABLE_CPU_FEATURES`` (read once, at load) turns NumPy's dispatch targets above AVX2 off,
so every machine with AVX2 and FMA runs the same loops; the record names the targets in use
(`numpy_simd`).
"""

from __future__ import annotations

import importlib
import os
import platform
import sys
from pathlib import Path

CORETYPE_ENV = "OPENBLAS_CORETYPE"
PINNED_CORETYPE = "Haswell"
NUMPY_FEATURES_ENV = "NPY_DISABLE_CPU_FEATURES"
# NumPy's x86-64 dispatch targets above AVX2 and FMA (X86_V3).
PINNED_NUMPY_DISABLED = "X86_V4 AVX512_ICL AVX512_SPR"
# What the Haswell kernels execute beyond the x86-64 baseline.
_NEEDED_FLAGS = frozenset({"avx2", "fma"})


def _cpu_flags() -> frozenset[str]:
    try:
        text = Path("/proc/cpuinfo").read_text()
    except OSError:
        return frozenset()
    for line in text.splitlines():
        if line.startswith("flags"):
            return frozenset(line.partition(":")[2].split())
    return frozenset()


def can_pin() -> bool:
    """Whether this machine runs the pinned kernels (x86-64 with AVX2 and FMA)."""
    return platform.machine().lower() in ("x86_64", "amd64") and _cpu_flags() >= _NEEDED_FLAGS


def pin_cpu_kernels() -> None:
    """Ask OpenBLAS for the pinned kernels and NumPy for loops up to AVX2, each unless the user
    chose otherwise, the CPU lacks them or NumPy is loaded already (then it is too late, and
    the record says which ran)."""
    if "numpy" in sys.modules or not can_pin():
        return
    os.environ.setdefault(CORETYPE_ENV, PINNED_CORETYPE)
    os.environ.setdefault(NUMPY_FEATURES_ENV, PINNED_NUMPY_DISABLED)


def numpy_simd() -> list[str]:
    """NumPy's dispatch targets (beyond its baseline) that this process runs."""
    umath = importlib.import_module("numpy._core._multiarray_umath")  # NumPy's own, no stubs
    features: dict[str, bool] = umath.__cpu_features__
    return [str(f) for f in umath.__cpu_dispatch__ if features.get(f)]


def blas_kernels() -> list[str]:
    """The kernels of each OpenBLAS loaded in this process (NumPy's, SciPy's), in load order."""
    from threadpoolctl import threadpool_info

    return [str(info.get("architecture")) for info in threadpool_info()
            if info.get("internal_api") == "openblas"]


def blas_kernels_pinned() -> bool:
    """Whether every OpenBLAS loaded runs the pinned kernels."""
    kernels = blas_kernels()
    return bool(kernels) and all(k.lower() == PINNED_CORETYPE.lower() for k in kernels)
