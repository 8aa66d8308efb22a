"""benchmarks/bookkeeping_ops.py: on a short flight's final state, each bookkeeping operation
gives what the one it replaced gives (the vertex distances within 10 µm on MAZE, whose triangles
are walls and floors)."""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks.bookkeeping_ops import measure


def test_each_operation_agrees_with_the_one_it_replaced() -> None:
    ops = {op["operation"].split(" (")[0]: op for op in measure("maze", 30.0, 1)}
    assert set(ops) == {"surface points", "thinning a snapshot", "TSDF at 20,000 points",
                        "vertex distances", "recall count"}
    for name, op in ops.items():
        assert op["ours_s"] > 0.0 and op["reference_s"] > 0.0
        if name != "vertex distances":
            assert op["agree"] == "identical", (name, op["agree"])
    assert ops["vertex distances"]["agree"].startswith("0 over 10 µm apart")
