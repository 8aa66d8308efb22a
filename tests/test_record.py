"""The reproducibility record of a run: complete, stable, and never fatal."""

from __future__ import annotations

from pathlib import Path

import pytest

from areas import load_area
from flybo import record as record_module
from flybo.record import config_hash, reproducibility_record
from planners.registry import spec
from sim.config import preset


def _record() -> dict[str, object]:
    return reproducibility_record(
        area=load_area("maze"), planner_id="classic-v1",
        planner_config=spec("classic-v1").config_model().model_dump(mode="json"),
        preset_name="default", preset=preset("default"), seed=3, speed_factor=0.97)


def test_the_record_names_everything_that_produced_the_run() -> None:
    rec = _record()
    assert rec["missing"] == []
    assert rec["seed"] == 3
    assert rec["preset"] == {"name": "default", "sha256": config_hash(preset("default"))}
    area = rec["area"]
    assert isinstance(area, dict) and area["name"] == "maze"
    assert area["generator"] == "maze-g1-s0" and len(area["sha256"]) == 64
    planner = rec["planner"]
    assert isinstance(planner, dict) and planner["id"] == "classic-v1"
    assert len(planner["code_sha256"]) == 64 and len(planner["config_sha256"]) == 64
    code = rec["code"]
    assert isinstance(code, dict) and len(code["sources_sha256"]) == 64
    assert code["git"] is not None and len(code["git"]["commit"]) == 40
    libraries = rec["libraries"]
    assert isinstance(libraries, dict)
    assert {"python", "numpy", "numba", "open3d", "pybullet", "ruckig"} <= set(libraries)
    assert all(libraries.values())
    machine = rec["machine"]
    assert isinstance(machine, dict) and machine["speed_factor"] == 0.97 and machine["cores"]
    assert isinstance(rec["benchmark_version"], str) and rec["components"]


def test_two_records_of_the_same_inputs_agree() -> None:
    assert _record() == _record()


def test_presets_differ_by_content_not_only_name() -> None:
    assert config_hash(preset("default")) != config_hash(preset("exact"))
    changed = preset("default").model_copy(update={"recall_interval_s": 10.0})
    assert config_hash(changed) != config_hash(preset("default"))


def test_a_record_without_git_says_what_is_missing(monkeypatch: pytest.MonkeyPatch,
                                                   tmp_path: Path) -> None:
    monkeypatch.setattr(record_module, "_ROOT", tmp_path)
    record_module._process_code.cache_clear()
    monkeypatch.setattr(record_module, "LIBRARIES", (*record_module.LIBRARIES, "no-such-lib"))
    rec = _record()
    assert rec["code"]["git"] is None  # type: ignore[index]
    missing = rec["missing"]
    assert isinstance(missing, list)
    assert any(m.startswith("git:") for m in missing)
    assert any(m.startswith("no-such-lib:") for m in missing)
    record_module._process_code.cache_clear()

