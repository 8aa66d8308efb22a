"""Fingerprints of short exact-preset flights of every registered planner on MAZE.

A fingerprint is the SHA-256 of a run's `result.json` with the fields that measure the machine
(wall time, per-frame costs, planning times in ms) left out, so that a change to how the episode
is organised that keeps its behaviour keeps every fingerprint. A change that alters behaviour
changes the benchmark version. The flights run on the pinned OpenBLAS kernels and NumPy loops
(`flybo.cpu_kernels`; the script imports `flybo` first), as every flight of the benchmark does.
Regenerate with

    .venv/bin/python tests/sim/episode_fingerprints.py --write
"""

from __future__ import annotations

import argparse
import hashlib
import json
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any

import flybo  # noqa: F401  before NumPy loads: it pins the CPU kernels

if TYPE_CHECKING:
    from sim.result import EpisodeResult

STORE = Path(__file__).with_name("episode_fingerprints.json")
AREA = "maze"
SEED = 0
SECONDS = 40.0
# Measured on the machine, not simulated: these vary from run to run.
_MACHINE_FIELDS = ("wall_seconds", "frame_costs_ms", "planning_time_ms", "reproducibility")


def canonical_result(payload: dict[str, Any]) -> dict[str, Any]:
    return {k: v for k, v in payload.items() if k not in _MACHINE_FIELDS}


def fingerprint(payload: dict[str, Any]) -> str:
    text = json.dumps(canonical_result(payload), sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(text.encode()).hexdigest()


def run_flight(planner_id: str) -> EpisodeResult:
    """The fingerprinted flight: `planner_id` on `AREA`, exact preset, `SEED`, `SECONDS`."""
    from areas import load_area, load_ground_truth
    from planners.registry import make
    from sim.config import preset
    from sim.episode import run_episode

    area = load_area(AREA)
    return run_episode(area, load_ground_truth(area), make(planner_id), preset("exact"), SEED,
                       planner_name=planner_id, preset_name="exact", seconds=SECONDS)


def run_payload(planner_id: str) -> dict[str, Any]:
    return run_flight(planner_id).to_json()


def planner_ids() -> list[str]:
    from planners.registry import planner_ids as ids

    return ids()


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--write", action="store_true", help="store the fingerprints")
    args = parser.parse_args(argv)
    stored = json.loads(STORE.read_text()) if STORE.exists() else {}
    found = {pid: fingerprint(run_payload(pid)) for pid in planner_ids()}
    for pid, fp in found.items():
        mark = "same" if stored.get(pid) == fp else "CHANGED"
        print(f"{pid:20s} {fp[:16]} {mark}")
    if args.write:
        STORE.write_text(json.dumps(found, indent=2, sort_keys=True) + "\n")
    return 0


if __name__ == "__main__":
    sys.path.insert(0, str(Path(__file__).resolve().parents[2]))
    sys.exit(main())
