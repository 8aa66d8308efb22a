"""The size of a baseline dataset per run, and the full suite's estimated from it.

A dataset's size is a part per run (result, metrics, reproducibility record) and a part per
simulated second (the series: explored volume each second, recall every 20 s). Both are
measured on a real dataset: the file as written, and the same runs written without their
series. The full suite (7 planners x 11 areas x 5 runs at the plateau times: 385 runs,
393,750 simulated seconds) is then 385 x the per-run part + 393,750 x the per-second part,
against the budget of 20 MiB (`docs/baselines.md`).

    python benchmarks/baseline_size.py --dataset FILE      # its runs of --preset (default)
    python benchmarks/baseline_size.py --runs 2 --seconds 60   # fly a small suite first
    ... --series-from DIR/result.json   # also: the series of one whole flight (`flybo run`)

Short runs measure the series' cost per second on short series; `--series-from` measures it on
one flight of a whole plateau time as well, and the estimate takes the larger of the two. The
estimate is the full suite's in the default preset (`docs/baselines.md`).

Without `--dataset` it flies `--planners` x `--areas` x `--runs` of `--seconds` in the
`--preset` preset with the worker's own `execute_run` into a scratch SQLite service, then
exports it as `flybo baselines export` does.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

from server.baseline_format import Dataset, encode, read_dataset
from server.baselines import suite_of

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import print_table, write_json

FULL_RUNS = 7 * 11 * 5
FULL_SIMULATED_S = 5 * 7 * (700 + 600 + 750 + 1650 + 700 + 750 + 1650 + 900 + 550 + 1200 + 1800)
BUDGET_BYTES = 20 * 1024 * 1024


def fly_suite(folder: Path, planners: list[str], areas: list[str], runs: int, seconds: float,
              preset: str) -> Dataset:
    from flybo.record import reproducibility_record
    from flybo.versions import benchmark_version
    from server.baselines import export_dataset
    from server.catalog import sync_builtin_planners
    from server.db import make_engine, make_session_factory, session_scope
    from server.jobs import create_job
    from server.migrate import upgrade
    from server.models import User
    from server.schemas import JobCreate
    from server.settings import Settings
    from worker.runner import execute_run, install_record_builder

    install_record_builder(reproducibility_record)
    settings = Settings(data_dir=folder / "data",
                        database_url=f"sqlite:///{folder / 'flybo.sqlite'}")
    engine = make_engine(settings.db_url)
    upgrade(engine)
    factory = make_session_factory(engine)
    ids: list[int] = []
    with session_scope(factory) as s:
        sync_builtin_planners(s)
        user = User(name="benchmark")
        s.add(user)
        s.flush()
        for planner in planners:
            created = create_job(s, settings, user, JobCreate(
                planner=planner, areas=areas, runs=runs, seconds=seconds, preset=preset))
            ids += [run_id for run_id, _ in created.runs]
    for run_id in ids:
        print(f"run {run_id}: {execute_run(run_id, settings)}", flush=True)
    with factory() as s:
        dataset = export_dataset(s, benchmark_version())
    engine.dispose()
    return dataset


def series_per_second(result_json: Path) -> float:
    """xz bytes per simulated second of one flight's series, encoded as a dataset holds them
    (base64 of float32), beside a dataset's other runs' series as `encode` compresses them."""
    import base64
    import json
    import lzma

    import numpy as np

    payload = json.loads(result_json.read_text())
    series = {k: base64.b64encode(np.asarray(v, dtype="<f4").tobytes()).decode("ascii")
              for k, v in payload["series"].items()}
    size = len(lzma.compress(json.dumps(series).encode(), preset=9 | lzma.PRESET_EXTREME))
    empty = len(lzma.compress(json.dumps({k: "" for k in series}).encode(),
                              preset=9 | lzma.PRESET_EXTREME))
    return (size - empty) / float(payload["sim_seconds"])


def measure(dataset: Dataset, long_series: float | None = None) -> dict[str, float]:
    whole = len(encode(dataset))
    bare = len(encode(dataset.model_copy(update={
        "runs": [r.model_copy(update={"series": None}) for r in dataset.runs]})))
    runs, simulated = len(dataset.runs), dataset.suite.simulated_s
    # The worst case per run: a dataset of one run, which shares nothing with other runs.
    alone = len(encode(dataset.model_copy(update={"runs": [
        dataset.runs[0].model_copy(update={"series": None})]})))
    per_run, measured = bare / runs, (whole - bare) / simulated
    per_second = max(measured, long_series or 0.0)
    estimate = FULL_RUNS * per_run + FULL_SIMULATED_S * per_second
    worst = FULL_RUNS * alone + FULL_SIMULATED_S * per_second
    return {"runs": runs, "simulated_s": simulated, "bytes": whole, "bytes_without_series": bare,
            "per_run_bytes": per_run, "series_bytes_per_simulated_s_measured": measured,
            "series_bytes_per_simulated_s": per_second,
            "series_bytes_per_simulated_s_long_flight": long_series or 0.0,
            "full_suite_runs": FULL_RUNS, "full_suite_simulated_s": FULL_SIMULATED_S,
            "full_suite_estimate_bytes": estimate, "one_run_alone_bytes": alone,
            "full_suite_worst_case_bytes": worst, "budget_bytes": BUDGET_BYTES,
            "within_budget": estimate <= BUDGET_BYTES}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--dataset", type=Path, default=None)
    parser.add_argument("--planners", nargs="+", default=["classic", "rapid"])
    parser.add_argument("--areas", nargs="+", default=["maze", "facility-a"])
    parser.add_argument("--runs", type=int, default=2)
    parser.add_argument("--seconds", type=float, default=60.0)
    parser.add_argument("--preset", default="default")
    parser.add_argument("--series-from", type=Path, default=None, metavar="RESULT_JSON")
    args = parser.parse_args()
    if args.dataset is not None:
        # Only the runs of `--preset`: exact runs of different seeds can be identical, and
        # would compress better than a real suite's.
        dataset = read_dataset(args.dataset)
        runs = [r for r in dataset.runs if r.preset == args.preset]
        dataset = dataset.model_copy(update={"runs": runs, "suite": suite_of(runs)})
    else:
        with tempfile.TemporaryDirectory(prefix="flybo-baseline-size-") as tmp:
            dataset = fly_suite(Path(tmp), args.planners, args.areas, args.runs,
                                args.seconds, args.preset)
    long_series = series_per_second(args.series_from) if args.series_from else None
    m = measure(dataset, long_series)
    mib = 1024 * 1024
    print_table("Baseline dataset size (xz-compressed JSON)", ["quantity", "value"], [
        ["runs measured", m["runs"]], ["simulated s measured", f"{m['simulated_s']:,.0f}"],
        ["file", f"{m['bytes'] / 1024:.1f} KiB"],
        ["per run (result, metrics, record)", f"{m['per_run_bytes'] / 1024:.2f} KiB"],
        ["series per simulated s, these runs",
         f"{m['series_bytes_per_simulated_s_measured']:.2f} B"],
        ["series per simulated s, whole flight",
         f"{long_series:.2f} B" if long_series is not None else "not measured"],
        ["full suite (385 runs, 393,750 s)", f"{m['full_suite_estimate_bytes'] / mib:.2f} MiB"],
        ["one run alone, without series", f"{m['one_run_alone_bytes'] / 1024:.2f} KiB"],
        ["full suite if runs shared nothing",
         f"{m['full_suite_worst_case_bytes'] / mib:.2f} MiB"],
        ["budget", f"{BUDGET_BYTES / mib:.0f} MiB"]])
    write_json("baseline_size", m)


if __name__ == "__main__":
    main()
