"""A built-in planner gives the same run in the sandbox as in process (planning time not
charged), and the map it sees through shared memory is the runner's map."""

from __future__ import annotations

import zlib
from pathlib import Path

import numpy as np

from areas import load_area, load_ground_truth
from planners.registry import make
from sim.config import preset
from sim.episode import run_episode
from sim.interface import Observation, Plan, PlannerContext
from worker.sandbox.proxy import SandboxedPlanner


def test_classic_in_the_sandbox_matches_in_process() -> None:
    area = load_area("maze")
    truth = load_ground_truth(area)
    config = preset("exact")
    direct = run_episode(area, truth, make("classic"), config, 2, seconds=40.0)
    with SandboxedPlanner(builtin="classic") as planner:
        boxed = run_episode(area, truth, planner, config, 2, seconds=40.0)
    assert boxed.status == direct.status
    assert boxed.iterations == direct.iterations > 3
    np.testing.assert_array_equal(boxed.volume_m3, direct.volume_m3)
    assert boxed.path_length_m == direct.path_length_m


CHECKSUMS = '''
import zlib
from dataclasses import replace

from planners.classic import Classic


class Checksums(Classic):
    """Classic, reporting checksums of the map layers it sees."""

    def plan(self, obs):
        plan = super().plan(obs)
        m = obs.map
        sums = {name: zlib.crc32(getattr(m, name).tobytes())
                for name in ("state", "surface_weight", "surface_directions")}
        return replace(plan, info={**plan.info, **sums})
'''


class _Comparing:
    """Runs a sandboxed planner and records whether its map matched the runner's at each call."""

    def __init__(self, inner: SandboxedPlanner) -> None:
        self.inner = inner
        self.mismatches: list[str] = []
        self.calls = 0

    def reset(self, ctx: PlannerContext) -> None:
        self.inner.reset(ctx)

    def plan(self, obs: Observation) -> Plan:
        plan = self.inner.plan(obs)
        self.calls += 1
        for name in ("state", "surface_weight", "surface_directions"):
            if plan.info.get(name) != zlib.crc32(getattr(obs.map, name).tobytes()):
                self.mismatches.append(f"{name} at t={obs.time:.2f}")
        return plan


def test_the_sandbox_sees_the_runner_map_and_surface_layers(tmp_path: Path) -> None:
    area = load_area("maze")
    code = tmp_path / "code"
    code.mkdir()
    (code / "planner.py").write_text(CHECKSUMS)
    with SandboxedPlanner(code=code) as boxed:
        comparing = _Comparing(boxed)
        run_episode(area, load_ground_truth(area), comparing, preset("exact"), 1, seconds=25.0)
    assert comparing.calls > 3
    assert comparing.mismatches == []
