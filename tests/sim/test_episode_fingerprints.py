"""Every registered planner flies MAZE on the exact preset exactly as the stored fingerprints
say: a change to how the episode is organised must not change what it does (a change that does
is a new benchmark version, and the fingerprints are regenerated with
`tests/sim/episode_fingerprints.py --write`)."""

from __future__ import annotations

import json

import pytest

from tests.sim.episode_fingerprints import STORE, fingerprint, planner_ids, run_payload

_STORED: dict[str, str] = json.loads(STORE.read_text())


def test_every_planner_has_a_fingerprint() -> None:
    assert sorted(_STORED) == planner_ids()


@pytest.mark.slow
@pytest.mark.parametrize("planner_id", sorted(_STORED))
def test_flight_matches_its_fingerprint(planner_id: str) -> None:
    assert fingerprint(run_payload(planner_id)) == _STORED[planner_id], (
        f"{planner_id} on MAZE (exact preset) no longer flies as stored")
