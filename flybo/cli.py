"""The `flybo` command line: thin subcommands over the library.

The simulation stack (areas, planners, sim: Open3D, numba) is imported by the commands that
use it, so that the service and client commands (`flybo.service_cli`) start without it.
"""

from __future__ import annotations

import argparse
import json
import math
import shutil
import sys
import tempfile
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any

from pydantic import ValidationError
from rich.console import Console
from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn
from rich.table import Table

from flybo.errors import CliError
from flybo.service_cli import add_service_commands, check_planner, run_service_command

__all__ = ["CliError", "main"]

if TYPE_CHECKING:
    from areas import Area, GroundTruth
    from planners.api import Planner
    from sim.config import EpisodeConfig
    from sim.result import EpisodeResult


def _positive(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None
    if not (value > 0 and math.isfinite(value)):
        raise argparse.ArgumentTypeError(f"must be a positive number, got {text}")
    return value


def _seed(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not an integer: {text!r}") from None
    if value < 0:
        raise argparse.ArgumentTypeError(f"must be >= 0, got {value}")
    return value


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="flybo", description="Benchmark autonomous exploration planners of flying robots."
    )
    sub = parser.add_subparsers(dest="command", required=True)
    run = sub.add_parser("run", help="run one exploration episode and write its results")
    run.add_argument("--area", required=True, help="area name (see `flybo areas`)")
    run.add_argument("--planner", required=True, help="planner name (see `flybo planners`)")
    run.add_argument("--seed", type=_seed, default=0, help="random seed (default 0)")
    run.add_argument("--seconds", type=_positive, default=None,
                     help="simulated seconds (default: the area's plateau time)")
    run.add_argument("--preset", default="default", help="episode preset (default 'default')")
    run.add_argument("--planner-config", default=None, metavar="JSON",
                     help="planner settings as a JSON object")
    run.add_argument("--out", required=True, type=Path, help="output folder (must not exist)")
    run.add_argument("--quiet", action="store_true", help="no progress bar")
    areas = sub.add_parser("areas", help="list areas, or import a mesh as a new one")
    areas_sub = areas.add_subparsers(dest="areas_command")
    areas_sub.add_parser("list", help="built-in and imported areas (the default)")
    imp = areas_sub.add_parser("import", help="import a mesh file (OBJ, PLY, STL, OFF, GLB/GLTF, "
                               "DAE) as an area that `flybo run --area NAME` can use")
    imp.add_argument("file", type=Path, help="mesh file")
    imp.add_argument("--name", required=True, help="area name: lower case, digits, hyphens")
    imp.add_argument("--scale", type=_positive, default=1.0,
                     help="metres per file unit, after the file's own unit (default 1)")
    imp.add_argument("--up", default="z", choices=["x", "y", "z", "-x", "-y", "-z"],
                     help="the file's up axis (default z)")
    imp.add_argument("--voxel-size", type=_positive, default=0.1,
                     help="occupancy voxel edge in metres (default 0.1)")
    imp.add_argument("--overwrite", action="store_true", help="replace an area of that name")
    show = areas_sub.add_parser("show", help="an area's Table 1 statistics, measured from its "
                                "mesh and ground truth, beside the paper's values")
    show.add_argument("name", help="area name")
    build = areas_sub.add_parser("build", help="build the ground truth and thumbnails of an "
                                 "area (or all built-in areas) into the cache")
    build.add_argument("name", help="area name, or 'all' for every built-in area")
    planners = sub.add_parser("planners", help="list the registered planners, or check a file")
    planners_sub = planners.add_subparsers(dest="planners_command")
    planners_sub.add_parser("list", help="the registered planners (the default)")
    check = planners_sub.add_parser("check", help="run the upload checks and the sandboxed dry "
                                    "run on a planner file (.py or .zip) locally")
    check.add_argument("file", type=Path)
    sub.add_parser("presets", help="list the episode presets")
    add_service_commands(sub)
    return parser


def main(argv: list[str] | None = None) -> None:
    args = _parser().parse_args(argv)
    try:
        if args.command == "run":
            _run(args)
        elif args.command == "areas" and args.areas_command == "import":
            _import_area(args)
        elif args.command == "areas" and args.areas_command == "show":
            _show_area(args.name)
        elif args.command == "areas" and args.areas_command == "build":
            _build_areas(args.name)
        elif args.command == "areas":
            _list_areas()
        elif args.command == "planners" and args.planners_command == "check":
            check_planner(args.file)
        elif args.command == "planners":
            _list_planners()
        elif args.command == "presets":
            _list_presets()
        else:
            run_service_command(args)
    except CliError as exc:
        print(f"flybo: error: {exc}", file=sys.stderr)
        raise SystemExit(2) from None
    except KeyboardInterrupt:
        print("flybo: interrupted", file=sys.stderr)
        raise SystemExit(130) from None


def _list_areas() -> None:
    from areas import area_names, load_area  # the simulation stack: on use
    from areas.registry import all_area_names

    built_in = set(area_names())
    for name in all_area_names():
        area = load_area(name)
        size = " x ".join(f"{v:.4g}" for v in area.extent)
        kind = "built-in" if name in built_in else "imported"
        print(f"{name:<16} {kind:<9} {size} m  plateau {area.plateau_s:g} s")


def _import_area(args: argparse.Namespace) -> None:
    from areas import load_ground_truth  # the simulation stack: on use
    from areas.importer import MeshImportError, import_mesh
    from areas.registry import store_area
    from areas.store import AreaStoreError

    try:
        area = import_mesh(args.file, args.name, scale=args.scale, up=args.up,
                           voxel_size=args.voxel_size)
        truth = load_ground_truth(area)  # checks the start and fills the cache now
        store_area(area, overwrite=args.overwrite)
    except (MeshImportError, AreaStoreError, ValueError) as exc:
        raise CliError(str(exc).splitlines()[0]) from None
    size = " x ".join(f"{v:.3g}" for v in area.extent)
    print(f"imported {area.name}: {len(area.triangles)} faces, {size} m, "
          f"observable volume {truth.observable_volume_m3:.1f} m³, "
          f"start {_rounded(area.start.position)}, plateau {area.plateau_s:g} s")
    print(f"  {_reach_note(truth)}")


def _reach_note(truth: GroundTruth) -> str:
    """What of the free space around the start the vehicle can fly through and see."""
    from areas.observability import ViewModel  # the simulation stack: on use

    note = (f"free space from the start {truth.free_volume_m3:.1f} m³, the vehicle reaches "
            f"{truth.reachable_volume_m3:.1f} m³ and sees {truth.observable_free_m3:.1f} m³")
    hidden = truth.unobservable_free_m3
    if hidden >= max(0.5, 0.005 * truth.free_volume_m3):
        width = 2 * ViewModel().safety_radius_m
        note += (f"; {hidden:.1f} m³ ({100 * hidden / truth.free_volume_m3:.1f} %) is out of "
                 f"reach and sight: behind openings narrower than the vehicle needs "
                 f"({width:g} m) or beyond the camera's range")
    return note


def _rounded(position: Any) -> list[float]:
    """A position to the centimetre, printed as a list."""
    return [round(float(v), 2) for v in position]


def _load_named_area(name: str) -> Area:
    from areas import UnknownAreaError, load_area  # the simulation stack: on use
    from areas.store import AreaStoreError

    try:
        return load_area(name)
    except (UnknownAreaError, AreaStoreError) as exc:
        raise CliError(str(exc).splitlines()[0]) from None


def _show_area(name: str) -> None:
    from areas import load_ground_truth  # the simulation stack: on use
    from areas.stats import TABLE1, measure

    area = _load_named_area(name)
    try:
        stats = measure(area, load_ground_truth(area))
    except ValueError as exc:
        raise CliError(f"{area.name}: {str(exc).splitlines()[0]}") from None
    paper = TABLE1.get(area.name)

    def size(v: tuple[float, float, float]) -> str:
        return " x ".join(f"{x:.3g}" for x in v)

    levels = ", ".join(f"{h:.1f}" for h in stats.level_heights)
    rooms = "-" if area.info.rooms is None else str(area.info.rooms)
    rows = [
        ("area (m²)", f"{stats.area_m2:.0f}", paper and f"{paper.area_m2:g}"),
        ("volume (m³)", f"{stats.volume_m3:.0f}", paper and f"{paper.volume_m3:g}"),
        ("bounding volume (m)", size(stats.bounding), paper and size(paper.bounding)),
        ("rooms", rooms, paper and ("-" if paper.rooms is None else str(paper.rooms))),
        ("levels", f"{stats.levels} (floors at {levels} m)", paper and str(paper.levels)),
        ("faces", f"{stats.faces:,}", paper and f"{paper.faces:,}"),
        ("indoor / outdoor", "indoor" if area.info.indoor else "outdoor", None),
        ("voxel size (m)", f"{area.voxel_size:g}", None),
        ("plateau (s)", f"{area.plateau_s:g}", None),
        ("start", f"{_rounded(area.start.position)}, yaw {area.start.yaw:.2f}",
         None),
    ]
    truth = load_ground_truth(area)
    print(f"{area.info.title} ({area.name})")
    print(f"  {'':<20} {'measured':<34} {'Table 1' if paper else ''}")
    for label, measured, table in rows:
        print(f"  {label:<20} {measured:<34} {table or ''}".rstrip())
    print(f"  {_reach_note(truth)}")


def _build_areas(name: str) -> None:
    from areas import area_names  # the simulation stack: on use
    from areas.ground_truth import ensure_cached
    from areas.thumbnail import write_thumbnails

    names = area_names() if name.strip().lower() == "all" else [name]
    total = time.perf_counter()
    for each in names:
        began = time.perf_counter()
        area = _load_named_area(each)
        generated = time.perf_counter()
        try:
            truth, cached = ensure_cached(area)
        except ValueError as exc:
            raise CliError(f"{area.name}: {str(exc).splitlines()[0]}") from None
        truthed = time.perf_counter()
        top, _ = write_thumbnails(area)
        done = time.perf_counter()
        print(f"{area.name:<12} mesh {generated - began:5.1f} s  ground truth "
              f"{truthed - generated:5.1f} s{' (cached)' if cached else ''}  thumbnails "
              f"{done - truthed:4.1f} s  {len(area.triangles):>8,} faces  "
              f"{len(truth.surface):>11,} surface points", flush=True)
    print(f"built {len(names)} area(s) in {time.perf_counter() - total:.1f} s; "
          f"thumbnails in {top.parent}")


def _list_planners() -> None:
    from planners.registry import planner_ids, spec  # the simulation stack: on use

    for planner_id in planner_ids():
        s = spec(planner_id)
        print(f"{planner_id:<16} {s.method or '-':<9} {s.description}")


def _list_presets() -> None:
    from sim.config import PRESETS  # the simulation stack: on use

    for name in sorted(PRESETS):
        print(name)


def _run(args: argparse.Namespace) -> None:
    # The simulation stack: on use.
    from areas import UnknownAreaError, load_area, load_ground_truth
    from flybo.record import reproducibility_record
    from planners.registry import PlannerConfigError, UnknownPlannerError, make, spec
    from sim.config import UnknownPresetError, preset
    from worker.result_folder import ResultFolderError, write_result_folder

    try:
        area = load_area(args.area)
        planner_spec = spec(args.planner)
        config = preset(args.preset)
        planner_config = json.loads(args.planner_config) if args.planner_config else {}
        if not isinstance(planner_config, dict):
            raise CliError("--planner-config must be a JSON object")
        planner = make(planner_spec.id, planner_config)
    except (UnknownAreaError, UnknownPlannerError, UnknownPresetError, PlannerConfigError) as exc:
        raise CliError(str(exc).splitlines()[0]) from None
    except (json.JSONDecodeError, ValidationError) as exc:
        raise CliError(f"--planner-config: {str(exc).splitlines()[0]}") from None
    out: Path = args.out
    if out.exists():
        raise CliError(f"output folder {out} already exists; choose a new --out")
    out.parent.mkdir(parents=True, exist_ok=True)
    truth = load_ground_truth(area)
    # Everything is written into a temporary sibling folder and renamed at the end, so an
    # interrupted run never leaves a folder that looks complete.
    staging = Path(tempfile.mkdtemp(prefix=f".{out.name}.", dir=out.parent))
    try:
        result = _run_with_progress(args, area, truth, planner, planner_spec.id, config, staging)
        record = reproducibility_record(
            area=area, planner_id=planner_spec.id,
            planner_config=planner.config.model_dump(mode="json"), preset_name=args.preset,
            preset=config, seed=args.seed, speed_factor=result.charge.get("speed_factor"))
        try:
            write_result_folder(result, staging, record)
        except ResultFolderError as exc:
            raise CliError(str(exc)) from None
        staging.chmod(0o755)  # mkdtemp makes it private
        staging.rename(out)
    except BaseException:
        shutil.rmtree(staging, ignore_errors=True)
        raise
    _print_summary({**result.to_json(), "reproducibility": record}, out,
                   len(result.mesh_triangles))


def _run_with_progress(
    args: argparse.Namespace,
    area: Area,
    truth: GroundTruth,
    planner: Planner,
    planner_id: str,
    config: EpisodeConfig,
    staging: Path,
) -> EpisodeResult:
    from sim.episode import run_episode  # the simulation stack: on use
    from worker.result_folder import RECORDING

    seconds = args.seconds if args.seconds is not None else area.plateau_s
    recording = staging / RECORDING
    if args.quiet:
        return run_episode(area, truth, planner, config, args.seed, planner_name=planner_id,
                           preset_name=args.preset, seconds=seconds, recording_path=recording)
    columns = (TextColumn("{task.description}"), BarColumn(),
               TextColumn("{task.completed:>6.0f}/{task.total:.0f} s"),
               TextColumn("V = {task.fields[volume]:7.1f} m³"), TimeElapsedColumn())
    with Progress(*columns, transient=False) as bar:
        task = bar.add_task(f"{area.name} · {planner_id}", total=seconds, volume=0.0)

        def progress(t: float, volume: float) -> None:
            bar.update(task, completed=t, volume=volume)

        result = run_episode(area, truth, planner, config, args.seed, planner_name=planner_id,
                             preset_name=args.preset, seconds=seconds, recording_path=recording,
                             progress=progress)
        bar.update(task, completed=seconds)
    return result


def _print_summary(payload: dict[str, Any], out: Path, mesh_triangles: int) -> None:
    from worker.result_folder import MESH, RECORDING, RESULT  # numpy: on use

    surface = payload["surface"]
    timing = payload["planning_time_ms"]

    def num(value: float | None, fmt: str) -> str:
        return "-" if value is None else format(value, fmt)

    table = Table(title=f"{payload['area']} · {payload['planner']} · seed {payload['seed']}")
    table.add_column("metric")
    table.add_column("value", justify="right")
    rows = [
        ("status", f"{payload['status']} ({payload['reason']})"),
        ("simulated / wall", f"{payload['sim_seconds']:.0f} s / {payload['wall_seconds']:.1f} s"),
        ("explored volume", f"{payload['explored_volume_m3']:.1f} m³"),
        ("observable volume", f"{payload['observable_volume_m3']:.1f} m³"),
        ("coverage", f"{payload['coverage']:.3f}"),
        ("collisions", str(payload["collisions"])),
        ("safety stops", str(payload.get("safety_stops", 0))),
        ("path length", f"{payload['path_length_m']:.1f} m"),
        ("iterations", str(payload["iterations"])),
        ("planning time mean / max", f"{timing['mean']:.1f} / {timing['max']:.1f} ms"),
        (f"surface F-score @ {surface['tau_m']} m", num(surface["fscore"], ".3f")),
        ("surface precision / recall",
         f"{num(surface['precision'], '.3f')} / {num(surface['recall'], '.3f')}"),
        ("surface RMSE", f"{num(surface['rmse_m'], '.4f')} m"),
        # An empty reconstruction (nothing within camera range) is scored as such, not lost.
        ("reconstructed mesh", f"{mesh_triangles:,} triangles" if mesh_triangles
         else "none: no surface was seen (an empty mesh.ply)"),
        ("time to 90 % coverage",
         f"{num(payload['metrics'].get('time_to_90_coverage_s'), '.0f')} s"),
        ("planning charged", f"{payload['planning_charge']['total_s']:.2f} s "
                             f"({payload['planning_charge']['mode']})"),
        ("benchmark version", str(payload["reproducibility"].get("benchmark_version"))),
    ]
    for key, value in rows:
        table.add_row(key, value)
    console = Console()
    console.print(table)
    console.print(f"results in {out}/ ({RESULT}, {RECORDING}, {MESH})")
