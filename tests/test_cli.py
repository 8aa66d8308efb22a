"""The `flybo` command line, run in-process: input errors, listings and one real short run."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from flybo.cli import main

RUN_SECONDS = 15


def _run_args(out: Path, **overrides: str) -> list[str]:
    options = {"--area": "maze", "--planner": "classic", "--seconds": str(RUN_SECONDS),
               "--preset": "exact", "--out": str(out), **overrides}
    args = ["run"]
    for key, value in options.items():
        args += [key, value]
    return [*args, "--quiet"]


def _exit_code(argv: list[str]) -> int | str | None:
    with pytest.raises(SystemExit) as info:
        main(argv)
    return info.value.code


def _snapshot(folder: Path) -> dict[str, bytes]:
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*"))
            if p.is_file()}


# -- input errors --------------------------------------------------------------------------------


def test_unknown_area_lists_the_known_areas(tmp_path: Path, capsys: pytest.CaptureFixture[str]
                                            ) -> None:
    out = tmp_path / "run"
    assert _exit_code(_run_args(out, **{"--area": "atlantis"})) == 2
    err = capsys.readouterr().err
    assert err.startswith("flybo: error:")
    assert "atlantis" in err
    assert "maze" in err
    assert not out.exists()
    assert list(tmp_path.iterdir()) == []


def test_unknown_planner_lists_the_known_planners(tmp_path: Path,
                                                  capsys: pytest.CaptureFixture[str]) -> None:
    assert _exit_code(_run_args(tmp_path / "run", **{"--planner": "teleport"})) == 2
    err = capsys.readouterr().err
    assert "teleport" in err
    assert "classic-v1" in err
    assert list(tmp_path.iterdir()) == []


def test_unknown_planner_version_lists_the_known_versions(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert _exit_code(_run_args(tmp_path / "run", **{"--planner": "classic-v9"})) == 2
    err = capsys.readouterr().err
    assert "v9" in err
    assert "classic-v1" in err


def test_unknown_preset_lists_the_presets(tmp_path: Path,
                                          capsys: pytest.CaptureFixture[str]) -> None:
    assert _exit_code(_run_args(tmp_path / "run", **{"--preset": "turbo"})) == 2
    err = capsys.readouterr().err
    assert "turbo" in err
    for name in ("default", "exact", "full"):
        assert name in err
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("seconds", ["-1", "0", "abc", "nan", "inf", ""])
def test_bad_seconds_is_a_usage_error(seconds: str, tmp_path: Path,
                                      capsys: pytest.CaptureFixture[str]) -> None:
    assert _exit_code(_run_args(tmp_path / "run", **{"--seconds": seconds})) == 2
    err = capsys.readouterr().err
    assert "--seconds" in err
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("seed", ["-3", "1.5", "x"])
def test_bad_seed_is_a_usage_error(seed: str, tmp_path: Path,
                                   capsys: pytest.CaptureFixture[str]) -> None:
    assert _exit_code(_run_args(tmp_path / "run", **{"--seed": seed})) == 2
    assert "--seed" in capsys.readouterr().err


def test_existing_out_folder_is_refused_and_left_alone(tmp_path: Path,
                                                       capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "previous"
    (out / "nested").mkdir(parents=True)
    (out / "result.json").write_text('{"keep": true}\n')
    (out / "nested" / "data.bin").write_bytes(b"\x00\x01\x02")
    before = _snapshot(out)
    assert _exit_code(_run_args(out)) == 2
    err = capsys.readouterr().err
    assert "already exists" in err
    assert str(out) in err
    assert _snapshot(out) == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["previous"]


def test_existing_out_file_is_refused(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "a-file"
    out.write_text("precious")
    assert _exit_code(_run_args(out)) == 2
    assert "already exists" in capsys.readouterr().err
    assert out.read_text() == "precious"


@pytest.mark.parametrize(
    ("config", "expected"),
    [
        ("[1]", "JSON object"),
        ('"text"', "JSON object"),
        ("3", "JSON object"),
        ("{not json", "--planner-config"),
        ('{"no_such_key": 1}', "classic-v3"),
        ('{"min_cluster_size": "many"}', "classic-v3"),
        ('{"min_cluster_size": 0}', "classic-v3"),
    ],
)
def test_bad_planner_config_is_refused(config: str, expected: str, tmp_path: Path,
                                       capsys: pytest.CaptureFixture[str]) -> None:
    assert _exit_code(_run_args(tmp_path / "run", **{"--planner-config": config})) == 2
    err = capsys.readouterr().err
    assert err.startswith("flybo: error:")
    assert expected in err
    assert len(err.strip().splitlines()) == 1
    assert list(tmp_path.iterdir()) == []


def test_bad_planner_config_message_names_the_key(tmp_path: Path,
                                                  capsys: pytest.CaptureFixture[str]) -> None:
    config = '{"no_such_key": 1}'
    assert _exit_code(_run_args(tmp_path / "run", **{"--planner-config": config})) == 2
    assert "no_such_key" in capsys.readouterr().err


def test_missing_required_arguments_is_a_usage_error(capsys: pytest.CaptureFixture[str]) -> None:
    assert _exit_code(["run", "--area", "maze"]) == 2
    err = capsys.readouterr().err
    assert "--planner" in err
    assert "--out" in err


def test_unknown_command_is_a_usage_error(capsys: pytest.CaptureFixture[str]) -> None:
    assert _exit_code(["fly"]) == 2
    assert "fly" in capsys.readouterr().err
    assert _exit_code([]) == 2


# -- listings ------------------------------------------------------------------------------------


def test_areas_lists_the_maze(capsys: pytest.CaptureFixture[str]) -> None:
    main(["areas"])
    out = capsys.readouterr().out
    lines = out.strip().splitlines()
    assert any(line.split()[0] == "maze" for line in lines)
    maze = next(line for line in lines if line.split()[0] == "maze")
    assert "20 x 20 x 2.5 m" in maze


def test_planners_lists_classic_v1(capsys: pytest.CaptureFixture[str]) -> None:
    from planners.registry import planner_ids

    main(["planners"])
    out = capsys.readouterr().out
    listed = [line.split()[0] for line in out.strip().splitlines()]
    assert listed == planner_ids()
    assert "classic-v1" in listed
    method = {line.split()[0]: line.split()[1] for line in out.strip().splitlines()}
    assert (method["nbvp-v1"], method["nbvp-v2"]) == ("variant", "original")


def test_presets_lists_every_preset(capsys: pytest.CaptureFixture[str]) -> None:
    from sim.config import PRESETS

    main(["presets"])
    out = capsys.readouterr().out
    assert out.split() == sorted(PRESETS)
    assert {"default", "exact", "full"} <= set(out.split())


# -- a real run ----------------------------------------------------------------------------------


def test_a_mesh_that_cannot_be_written_is_an_error_and_leaves_nothing(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch,
) -> None:
    from sim.open3d_any import o3d

    monkeypatch.setattr(o3d.io, "write_triangle_mesh", lambda *args, **kwargs: False)
    assert _exit_code(_run_args(tmp_path / "run", **{"--seconds": "3"})) == 2
    assert "could not write" in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == []  # neither the folder nor its staging copy



@pytest.mark.slow
def test_short_run_writes_its_results(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "run"
    main(["run", "--area", "maze", "--planner", "classic", "--seconds", str(RUN_SECONDS),
          "--preset", "exact", "--quiet", "--out", str(out)])
    captured = capsys.readouterr()
    assert str(out) in captured.out
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run"]  # no staging folder left
    assert sorted(p.name for p in out.iterdir()) == ["mesh.ply", "recording.npz", "result.json"]

    result = json.loads((out / "result.json").read_text())
    for key in ("area", "planner", "seed", "status", "sim_seconds", "wall_seconds",
                "explored_volume_m3", "observable_volume_m3", "coverage", "collisions",
                "path_length_m", "iterations", "planning_time_ms", "surface", "series"):
        assert key in result, key
    assert result["area"] == "maze"
    assert result["planner"] == "classic-v3"
    assert result["seed"] == 0
    assert result["preset"] == "exact"
    assert result["status"] == "succeeded"
    assert result["sim_seconds"] == RUN_SECONDS
    assert result["wall_seconds"] > 0
    assert result["collisions"] == 0
    assert result["iterations"] >= 1
    assert 0 < result["explored_volume_m3"] < result["observable_volume_m3"] * 1.5
    assert 0 < result["coverage"] <= 1
    assert result["path_length_m"] >= 0
    timing = result["planning_time_ms"]
    for key in ("mean", "median", "max"):
        assert math.isfinite(timing[key])
        assert timing[key] >= 0
    assert timing["max"] >= timing["mean"]
    assert timing["max"] >= timing["median"]
    surface = result["surface"]
    for key in ("tau_m", "precision", "recall", "fscore", "rmse_m"):
        assert key in surface, key
    assert surface["tau_m"] == pytest.approx(0.05)
    for key in ("precision", "recall", "fscore"):
        assert surface[key] is not None
        assert 0 <= surface[key] <= 1
    series = result["series"]
    for key in ("time_s", "explored_volume_m3", "recall_time_s", "surface_recall"):
        assert key in series, key
    assert series["time_s"] == [float(t) for t in range(RUN_SECONDS + 1)]
    assert len(series["explored_volume_m3"]) == RUN_SECONDS + 1
    assert np.all(np.diff(series["explored_volume_m3"]) >= 0)
    assert series["explored_volume_m3"][-1] == pytest.approx(result["explored_volume_m3"])
    assert len(series["recall_time_s"]) == len(series["surface_recall"])

    from sim.recording import Recording

    recording = Recording(out / "recording.npz")
    assert recording.header["area"] == "maze"
    assert recording.header["planner"] == "classic-v3"
    assert recording.header["seed"] == 0
    assert len(recording.pose_times) > 0
    assert recording.poses.shape == (len(recording.pose_times), 4)
    assert recording.pose_times[-1] <= RUN_SECONDS + 1e-6
    state = recording.map_state_at(RUN_SECONDS)
    assert tuple(state.shape) == tuple(recording.header["grid_shape"])
    assert np.count_nonzero(state) > 0

    mesh = out / "mesh.ply"
    assert mesh.stat().st_size > 0
    head = mesh.read_bytes()[:512]
    assert head.startswith(b"ply")
    assert b"element vertex" in head


def test_areas_import_then_run(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                               capsys: pytest.CaptureFixture[str]) -> None:
    """An imported mesh becomes an area that `flybo run` accepts by name."""
    import trimesh

    monkeypatch.setenv("FLYBO_DATA_DIR", str(tmp_path / "data"))
    monkeypatch.setenv("FLYBO_CACHE_DIR", str(tmp_path / "cache"))
    room = tmp_path / "room.obj"
    trimesh.creation.box(extents=(6.0, 5.0, 3.0)).export(room)
    main(["areas", "import", str(room), "--name", "room"])
    out = capsys.readouterr().out
    assert "imported room" in out
    main(["areas", "list"])
    assert "room" in capsys.readouterr().out
    # The same name again is refused and the stored area is kept.
    assert _exit_code(["areas", "import", str(room), "--name", "room"]) == 2
    assert "already exists" in capsys.readouterr().err
    main(["run", "--area", "room", "--planner", "classic", "--seconds", "8", "--preset", "exact",
          "--quiet", "--out", str(tmp_path / "run")])
    assert (tmp_path / "run" / "result.json").is_file()


def test_areas_import_errors_name_the_problem(tmp_path: Path,
                                              capsys: pytest.CaptureFixture[str]) -> None:
    text = tmp_path / "notes.txt"
    text.write_text("hello")
    assert _exit_code(["areas", "import", str(text), "--name", "notes"]) == 2
    assert "flybo: error:" in capsys.readouterr().err
    assert _exit_code(["areas", "import", str(text), "--name", "x", "--scale", "0"]) == 2
    assert "--scale" in capsys.readouterr().err


# -- areas show / build --------------------------------------------------------------------------


def test_areas_lists_all_eleven_built_in_areas(capsys: pytest.CaptureFixture[str]) -> None:
    from areas.stats import TABLE1

    main(["areas", "list"])
    lines = capsys.readouterr().out.strip().splitlines()
    built_in = [line.split()[0] for line in lines if line.split()[1] == "built-in"]
    assert built_in == sorted(TABLE1)


def test_areas_show_prints_measured_beside_table(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                 capsys: pytest.CaptureFixture[str]) -> None:
    monkeypatch.setenv("FLYBO_CACHE_DIR", str(tmp_path / "cache"))
    main(["areas", "show", "MAZE"])
    out = capsys.readouterr().out
    assert out.startswith("MAZE (maze)")
    rows = {line[:22].strip(): line[22:].split() for line in out.splitlines()[2:]}
    assert rows["bounding volume (m)"] == ["19.8", "x", "19.8", "x", "2.5", "20", "x", "20", "x",
                                           "2.5"]
    assert rows["levels"][0] == "1"
    assert rows["levels"][-1] == "1"
    assert rows["faces"] == [f"{1628:,}", "130"]
    assert float(rows["volume (m³)"][0]) > 800
    assert rows["volume (m³)"][1] == "1000"


def test_areas_show_and_build_reject_unknown_names(capsys: pytest.CaptureFixture[str]) -> None:
    for command in ("show", "build"):
        assert _exit_code(["areas", command, "atlantis"]) == 2
        err = capsys.readouterr().err
        assert err.startswith("flybo: error: unknown area 'atlantis'")
        assert len(err.strip().splitlines()) == 1
    assert _exit_code(["areas", "show"]) == 2  # the name is required


def test_areas_build_fills_the_cache(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                     capsys: pytest.CaptureFixture[str]) -> None:
    cache = tmp_path / "cache"
    monkeypatch.setenv("FLYBO_CACHE_DIR", str(cache))
    main(["areas", "build", "maze"])
    out = capsys.readouterr().out
    assert out.startswith("maze ")
    assert "ground truth" in out
    assert "(cached)" not in out
    assert "built 1 area(s)" in out
    assert (cache / "ground_truth" / "maze-g1-s0.npz").is_file()
    for view in ("top", "perspective"):
        png = cache / "thumbnails" / f"maze-g1-s0-{view}.png"
        assert png.read_bytes().startswith(b"\x89PNG")
    main(["areas", "build", "maze"])
    assert "(cached)" in capsys.readouterr().out


# -- start-up ------------------------------------------------------------------------------------


def test_the_command_loads_no_numerical_library_before_a_command_runs() -> None:
    """`flybo worker` sets the thread limits first thing, and OpenMP, OpenBLAS and numba read
    them when they load: loaded by the command line itself, they would keep every core."""
    probe = ("import sys, flybo.cli; print(','.join(m for m in ('numpy', 'numba', 'open3d', "
             "'scipy') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True,
                         check=True, timeout=120)
    assert out.stdout.strip() == ""


def test_a_run_that_sees_no_surface_keeps_its_results(tmp_path: Path,
                                                      capsys: pytest.CaptureFixture[str],
                                                      monkeypatch: pytest.MonkeyPatch) -> None:
    """A start with nothing within camera range: the run reconstructs no surface, is scored as
    such and keeps every file; the summary says so."""
    import trimesh

    from areas.area import Area, AreaInfo, StartPose
    from areas.store import save_area

    monkeypatch.setenv("FLYBO_DATA_DIR", str(tmp_path / "data"))
    monkeypatch.setenv("FLYBO_CACHE_DIR", str(tmp_path / "cache"))
    box = trimesh.creation.box(extents=(1.0, 1.0, 1.0))
    box.apply_translation((27.0, 27.0, 0.5))
    save_area(Area(
        name="far", vertices=np.asarray(box.vertices, dtype=np.float64),
        triangles=np.asarray(box.faces, dtype=np.int32), bounds_min=np.zeros(3),
        bounds_max=np.array([30.0, 30.0, 4.0]),
        start=StartPose(position=np.array([3.0, 3.0, 2.0]), yaw=0.0), plateau_s=300.0,
        voxel_size=0.2, info=AreaInfo(title="far", rooms=None, levels=1,
                                      complexity="imported", indoor=False)))
    out = tmp_path / "run"
    main(["run", "--area", "far", "--planner", "classic", "--seconds", "3", "--preset", "exact",
          "--out", str(out)])
    assert "no surface was seen" in capsys.readouterr().out
    assert sorted(p.name for p in out.iterdir()) == ["mesh.ply", "recording.npz", "result.json"]
    assert "element vertex 0" in (out / "mesh.ply").read_text()
    result = json.loads((out / "result.json").read_text())
    assert result["surface"]["recall"] in (0.0, None)


def test_the_reference_user_name_is_reserved(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                             capsys: pytest.CaptureFixture[str]) -> None:
    """No one gets a token of the published baselines' owner, so no one submits as it."""
    monkeypatch.setenv("FLYBO_DATA_DIR", str(tmp_path / "data"))
    monkeypatch.setenv("FLYBO_DATABASE_URL", f"sqlite:///{tmp_path / 'flybo.sqlite'}")
    assert _exit_code(["tokens", "create", "--user", "Flybo-Reference"]) == 2
    assert "reserved" in capsys.readouterr().err
    main(["tokens", "create", "--user", "alice"])
    assert capsys.readouterr().out.startswith("flybo_")
