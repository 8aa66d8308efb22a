"""The held-out board on the front page: how each planner scores on the held-out areas (of the
current generation, `server.heldout`) beside its public score, and the gap between them.

The score is the mean coverage over the areas of a board. A planner tuned to the public areas'
layouts scores higher there than on held-out ones generated alike: a large positive gap (public
minus held-out, in percentage points) is a sign of overfitting. The held-out areas are shown by
their opaque names only.
"""

from __future__ import annotations

from sqlalchemy.orm import Session

from server.heldout import current_generation
from server.leaderboard import build_leaderboard
from server.models import HELDOUT_SPLIT
from web.html import DASH, esc, num, planner_link, table, td


def heldout_section(session: Session, preset: str, version: str) -> str:
    """The held-out board's table, with each planner's public score and gap."""
    generation = current_generation(session)
    board = build_leaderboard(session, preset, benchmark_version=version,
                              scope=(HELDOUT_SPLIT, generation))
    headers = [("Rank", "by mean coverage rank over the held-out areas"), ("Planner", ""),
               ("Areas", "held-out areas with results"),
               ("Held-out", "mean coverage over the held-out areas, %"),
               ("Public", "mean coverage over the public areas, %"),
               ("Gap", "public minus held-out mean coverage, percentage points: a large "
                       "positive gap hints at overfitting to the public areas")]
    rows = []
    for p in board.overall:
        gap, mine = p.public_gap, p.public_mean_coverage
        rows.append(
            f"<tr data-planner='{esc(p.planner)}'>{td(str(p.rank), p.rank, 'num')}"
            f"{td(planner_link(p.planner, p.builtin, p.method), p.planner)}"
            f"{td(str(p.areas), p.areas, 'num')}"
            f"{td(num(p.mean_coverage, 1, 100), p.mean_coverage, 'num')}"
            f"{td(num(mine, 1, 100) if mine is not None else DASH, mine, 'num')}"
            f"{td(num(gap, 1, 100) if gap is not None else DASH, gap, 'num gap')}</tr>")
    return (f"<h2 id='heldout'>Held-out board</h2><p>Areas generated from seeds only the "
            f"service knows (generation {generation}); their scenes are not published. Results "
            "of older generations are never ranked with these.</p>"
            + table("Held-out coverage, % (mean over areas), and the gap to the public board",
                    headers, rows, table_id="heldout-table",
                    empty="No held-out results yet."))
