"""`flybo baselines export | import | verify` (`docs/baselines.md`).

Export and import work on the service's database (the `FLYBO_*` settings, as `flybo tokens`);
verify re-flies sampled cells of a dataset on this machine (`flybo.baselines_verify`).
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from flybo.baselines_load import SHIPPED_DATASET, current_benchmark_version, load_file
from flybo.errors import CliError


def add_baselines_command(sub: Any) -> None:
    baselines = sub.add_parser("baselines", help="baseline datasets: export a service's "
                               "results, import them as reference results, verify them")
    cmds = baselines.add_subparsers(dest="baselines_command", required=True)
    export = cmds.add_parser("export", help="write the succeeded runs of built-in planners of "
                             "one benchmark version from the service's database")
    export.add_argument("--out", type=Path, required=True, help="dataset file (.json.xz)")
    export.add_argument("--benchmark-version", default=None,
                        help="default: this code's benchmark version")
    export.add_argument("--preset", action="append", default=None,
                        help="only this preset (repeatable; default: all)")
    imp = cmds.add_parser("import", help="load a dataset into the service's database as "
                          "reference results (one transaction: all or nothing)")
    imp.add_argument("file", type=Path)
    verify = cmds.add_parser("verify", help="re-fly sampled cells of a dataset on this "
                             "machine and check they agree with it")
    verify.add_argument("file", type=Path, nargs="?", default=SHIPPED_DATASET,
                        help=f"dataset file (default: the shipped one, {SHIPPED_DATASET.name})")
    verify.add_argument("--sample", type=int, default=5, help="cells to re-fly (default 5)")
    verify.add_argument("--seed", type=int, default=0, help="which cells (default 0)")
    verify.add_argument("--preset", action="append", default=None,
                        help="sample cells of this preset only (repeatable)")


def run_baselines(args: argparse.Namespace) -> None:
    if args.baselines_command == "export":
        _export(args)
    elif args.baselines_command == "import":
        _import(args.file)
    else:
        from flybo.baselines_verify import verify  # the simulation and the worker: on use

        verify(args.file, args.sample, args.seed, args.preset, current_benchmark_version())


def _export(args: argparse.Namespace) -> None:
    from flybo.local_commands import cli_settings, migrated
    from server.baseline_format import SUFFIX, write_dataset  # the service's code: on use
    from server.baselines import export_dataset
    from server.db import session_scope

    if not args.out.name.endswith(SUFFIX):
        raise CliError(f"--out must end in {SUFFIX} (an xz-compressed JSON document)")
    version = args.benchmark_version or current_benchmark_version()
    with session_scope(migrated(cli_settings())) as session:
        dataset = export_dataset(session, version, args.preset)
    if not dataset.runs:
        raise CliError(f"no succeeded runs of built-in planners of benchmark version "
                       f"{version}{' in ' + ', '.join(args.preset) if args.preset else ''}")
    try:
        size = write_dataset(dataset, args.out)
    except OSError as exc:
        raise CliError(f"cannot write {args.out}: {exc.strerror or exc}") from None
    suite = dataset.suite
    print(f"{args.out}: {suite.runs} runs of {len(dataset.planners)} planner(s) on "
          f"{len(dataset.areas)} area(s), benchmark version {version}, {size / 1024:.1f} KiB "
          f"({size / max(suite.runs, 1) / 1024:.2f} KiB per run)")


def _import(path: Path) -> None:
    from flybo.local_commands import cli_settings, migrated
    from server.baseline_format import DatasetError

    factory = migrated(cli_settings())
    try:
        done = load_file(factory, path, current_benchmark_version())
    except DatasetError as exc:
        raise CliError(f"{path}: {exc}; nothing was imported") from None
    assert done is not None
    print(f"{path}: {done.imported} reference run(s) of benchmark version "
          f"{done.benchmark_version} imported, {done.skipped} already there")
