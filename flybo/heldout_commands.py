"""`flybo heldout`: the operator's view of the held-out split (`server.heldout`), read from and
written to the service's database directly, like `flybo tokens`.

`rotate` starts a new generation of held-out seeds: new held-out areas, built when a job group
first asks for them; results on the old ones stay, labelled with their generation, and are
never ranked with the new ones. `list` shows the generations and each held-out area's family.
"""

from __future__ import annotations

import argparse
from typing import Any

from flybo.errors import CliError


def add_heldout_command(sub: Any) -> None:
    heldout = sub.add_parser("heldout", help="the held-out split: list its areas, rotate its "
                             "seeds (operators, on the service's database)")
    cmds = heldout.add_subparsers(dest="heldout_command", required=True)
    rotate = cmds.add_parser("rotate", help="start a new generation of held-out seeds")
    rotate.add_argument("--note", default="", help="why (kept with the generation)")
    cmds.add_parser("list", help="the generations and the held-out areas with their families")


def run_heldout(args: argparse.Namespace) -> None:
    from flybo.local_commands import cli_settings, migrated
    from server.db import session_scope  # the service's code: on use
    from server.heldout import current_generation, heldout_rows, heldout_source, rotate

    if args.heldout_command == "rotate" and len(args.note) > 1000:
        raise CliError("--note must be at most 1000 characters")
    with session_scope(migrated(cli_settings())) as session:
        if args.heldout_command == "rotate":
            before = current_generation(session)
            after = rotate(session, args.note)
            print(f"held-out generation {before} -> {after}: its areas are built when a job "
                  f"group with heldout=true first asks for them; results of generation {before} "
                  "stay on its own board")
            return
        print(f"current held-out generation: {current_generation(session)}")
        for row in heldout_rows(session):
            family = (heldout_source(row.stats) or ("?", 0))[0]
            print(f"{row.name}  generation {row.heldout_generation}  family {family}")
