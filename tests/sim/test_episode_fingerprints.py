"""Every registered planner has a stored fingerprint of its short exact flight on MAZE: a change
to how the episode is organised must not change what it does (a change that does is a new
benchmark version, and the fingerprints are regenerated with
`tests/sim/episode_fingerprints.py --write`). The flights themselves are flown, and compared
with the fingerprints, by `tests/planners/test_conformance.py`, whose flights they are."""

from __future__ import annotations

import json

from tests.sim.episode_fingerprints import STORE, planner_ids

_STORED: dict[str, str] = json.loads(STORE.read_text())


def test_every_planner_has_a_fingerprint() -> None:
    assert sorted(_STORED) == planner_ids()
