"""OpenBLAS's kernels are pinned (`flybo.blas`), so that a flight is the same on every x86-64
machine, and each run's record says which kernels ran."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest

from flybo.blas import CORETYPE_ENV, PINNED_CORETYPE, blas_kernels, blas_kernels_pinned, can_pin

needs_pin = pytest.mark.skipif(not can_pin(), reason="this CPU has no AVX2 and FMA (or is not "
                               "x86-64): OpenBLAS keeps its own choice, which the record names")


def _kernels_in_a_process(code: str, **env: str) -> list[str]:
    environ = {k: v for k, v in os.environ.items() if k != CORETYPE_ENV} | env
    out = subprocess.run([sys.executable, "-c", code + "\nfrom flybo.blas import blas_kernels\n"
                          "import json; print(json.dumps(blas_kernels()))"],
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


def test_the_record_names_the_kernels() -> None:
    from areas import load_area
    from flybo.record import reproducibility_record
    from sim.config import preset

    record = reproducibility_record(area=load_area("maze"), planner_id="classic-v2",
                                    planner_config={}, preset=preset("exact"),
                                    preset_name="exact", seed=0, speed_factor=1.0)
    kernels = record["libraries"]["openblas_kernels"]
    assert kernels and kernels == ",".join(blas_kernels())
