"""benchmarks/bookkeeping_ops.py: on a short flight's final state, each bookkeeping operation
gives what the one it replaced gives (the vertex distances within 10 µm on MAZE, whose triangles
are walls and floors)."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks.bookkeeping_ops import baseline_mesh, measure
from benchmarks.common import baseline_module

ROOT = Path(__file__).resolve().parents[1]


def test_each_operation_agrees_with_the_one_it_replaced() -> None:
    """This tree stands in as its own `--baseline` too: its surface points and mesh match its
    own."""
    ops = {op["operation"].split(" (")[0]: op for op in measure("maze", 30.0, 1, ROOT)}
    assert set(ops) == {"surface points", "surface points, against --baseline",
                        "thinning a snapshot", "TSDF at 20,000 points", "vertex distances",
                        "recall count", "final mesh", "final mesh, against --baseline"}
    assert ops.pop("surface points, against --baseline")["agree"] == "identical, same order"
    for name in ("final mesh", "final mesh, against --baseline"):
        mesh = ops.pop(name)
        assert mesh["agree"] == "the same mesh", (name, mesh["agree"])
    for name, op in ops.items():
        assert op["ours_s"] > 0.0 and op["reference_s"] > 0.0
        if name != "vertex distances":
            assert op["agree"] == "identical", (name, op["agree"])
    assert ops["vertex distances"]["agree"].startswith("0 over 10 µm apart")


def test_a_baseline_tree_before_the_compiled_mesh_is_timed_by_its_slabs(tmp_path: Path) -> None:
    (tmp_path / "sim").mkdir()
    (tmp_path / "sim" / "tsdf_slabs.py").write_text("def mesh_in_slabs(*args):\n    return args\n")
    assert baseline_mesh(tmp_path)(1, 2, 3) == (1, 2, 3)
    assert baseline_mesh(ROOT).__name__ == "marching_cubes"


def test_a_baseline_module_compiles_apart_from_its_tree(tmp_path: Path) -> None:
    """Another tree's module runs from a copy: numba's cache of its kernels is written beside
    the copy, not in that tree, whose own runs load its cache under their module names."""
    (tmp_path / "sim").mkdir()
    (tmp_path / "sim" / "kernels.py").write_text(
        "import numba\n\n\n@numba.njit(cache=True)\ndef twice(x):\n    return 2 * x\n")
    module = baseline_module(tmp_path, "sim/kernels.py", "baseline_test_kernels")
    assert module.twice(21) == 42
    assert not (tmp_path / "sim" / "__pycache__").exists()
    with pytest.raises(SystemExit, match=r"no sim/absent\.py in it"):
        baseline_module(tmp_path, "sim/absent.py", "baseline_absent")
