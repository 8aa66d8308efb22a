"""benchmarks/worker_scaling.py: the set-ups and durations it is given are checked before any
worker starts, and a named problem ends it."""

from __future__ import annotations

import argparse
import subprocess
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks.worker_scaling import SETUPS, _setups

SCRIPT = Path(__file__).resolve().parents[1] / "benchmarks" / "worker_scaling.py"


@pytest.mark.parametrize(("arguments", "message"), [
    (["--setups", "2:many"], "'2:many' is not WORKERS:LIMIT"),
    (["--setups", "0:one"], "'0:one' is not WORKERS:LIMIT"),
    (["--setups", "two:shared"], "'two:shared' is not WORKERS:LIMIT"),
    (["--seconds", "long"], "--seconds must be a number or 'plateau', not 'long'"),
    (["--seconds", "-5"], "--seconds positive"),
])
def test_bad_arguments_are_refused_naming_the_problem(arguments: list[str], message: str) -> None:
    done = subprocess.run([sys.executable, str(SCRIPT), *arguments], capture_output=True,
                          text=True, timeout=120, check=False)
    assert done.returncode == 2
    assert message in done.stderr
    assert "round 1" not in done.stdout


def test_the_setups_given_are_the_ones_measured() -> None:
    parser = argparse.ArgumentParser()
    assert _setups(parser, ["1:one", "2:shared"]) == [(1, "one"), (2, "shared")]
    assert _setups(parser, [f"{w}:{t}" for w, t in SETUPS]) == list(SETUPS)
