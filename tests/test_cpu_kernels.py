"""OpenBLAS's kernels and NumPy's SIMD loops are pinned (`flybo.cpu_kernels`), so that a flight
is the same on every x86-64 machine, and each run's record says which ran."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from flybo.cpu_kernels import (
    CORETYPE_ENV,
    NUMPY_FEATURES_ENV,
    PINNED_CORETYPE,
    blas_kernels,
    blas_kernels_pinned,
    can_pin,
    numpy_simd,
)

needs_pin = pytest.mark.skipif(not can_pin(), reason="this CPU has no AVX2 and FMA (or is not "
                               "x86-64): OpenBLAS keeps its own choice, which the record names")


def _kernels_in_a_process(code: str, **env: str) -> list[str]:
    environ = {k: v for k, v in os.environ.items()
               if k not in (CORETYPE_ENV, NUMPY_FEATURES_ENV)} | env
    code += "\nfrom flybo.cpu_kernels import blas_kernels\nimport json\n"
    out = subprocess.run([sys.executable, "-c", code + "print(json.dumps(blas_kernels()))"],
                         env=environ, capture_output=True, text=True, check=True)
    return list(json.loads(out.stdout.strip().splitlines()[-1]))


@needs_pin
def test_this_test_process_runs_the_pinned_kernels() -> None:
    import numpy  # noqa: F401
    import scipy.linalg  # noqa: F401  SciPy brings an OpenBLAS of its own

    assert len(blas_kernels()) == 2
    assert blas_kernels_pinned(), blas_kernels()


@needs_pin
def test_importing_flybo_first_pins_numpys_and_scipys_kernels() -> None:
    kernels = _kernels_in_a_process("import flybo, numpy, scipy.linalg")
    assert kernels == [PINNED_CORETYPE, PINNED_CORETYPE]


@needs_pin
def test_a_users_choice_or_a_late_import_is_kept_and_visible() -> None:
    """The pin never overrides the user; after NumPy is loaded it cannot act, and says so."""
    chosen = _kernels_in_a_process("import flybo, numpy", **{CORETYPE_ENV: "Sandybridge"})
    assert chosen == ["Sandybridge"]
    late = _kernels_in_a_process("import numpy, flybo\nassert 'OPENBLAS_CORETYPE' not in "
                                 "__import__('os').environ")
    assert len(late) == 1


@needs_pin
def test_importing_flybo_first_keeps_numpy_to_its_avx2_loops() -> None:
    """NumPy's AVX-512 loops are off wherever flybo is imported first; where the user chose,
    the choice stands."""
    code = ("import flybo, numpy, os, json\nfrom flybo.cpu_kernels import numpy_simd\n"
            f"print(json.dumps([os.environ.get({NUMPY_FEATURES_ENV!r}), numpy_simd()]))")

    def run(**env: str) -> list[object]:
        environ = {k: v for k, v in os.environ.items() if k != NUMPY_FEATURES_ENV} | env
        out = subprocess.run([sys.executable, "-c", code], env=environ, capture_output=True,
                             text=True, check=True)
        return list(json.loads(out.stdout.strip().splitlines()[-1]))

    disabled, targets = run()
    assert isinstance(disabled, str) and isinstance(targets, list)
    assert not set(disabled.split()) & set(targets), (disabled, targets)
    assert "X86_V3" in targets  # the AVX2 and FMA loops stay
    chosen, fewer = run(**{NUMPY_FEATURES_ENV: "X86_V3 X86_V4 AVX512_ICL AVX512_SPR"})
    assert chosen == "X86_V3 X86_V4 AVX512_ICL AVX512_SPR" and fewer == []


def test_the_record_names_the_kernels() -> None:
    from areas import load_area
    from flybo.record import reproducibility_record
    from sim.config import preset

    record = reproducibility_record(area=load_area("maze"), planner_id="classic-v2",
                                    planner_config={}, preset=preset("exact"),
                                    preset_name="exact", seed=0, speed_factor=1.0)
    kernels = record["libraries"]["openblas_kernels"]
    assert kernels and kernels == ",".join(blas_kernels())
    assert record["libraries"]["numpy_simd"] == ",".join(numpy_simd())


def test_a_sandboxed_planner_runs_the_workers_choice(tmp_path: Path) -> None:
    """The planner process, whose environment is built from scratch, gets the same pins."""
    from worker.sandbox.bwrap_command import host_environment

    env = host_environment(tmp_path)
    for name in (CORETYPE_ENV, NUMPY_FEATURES_ENV):
        assert env.get(name) == os.environ.get(name), name
