"""benchmarks/sim_speed_areas.py: each row's fingerprint names the flight, so that two trees'
`exact` runs are known to time the same one."""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks.sim_speed_areas import measure


def test_the_same_exact_flight_has_the_same_fingerprint_and_another_flight_another() -> None:
    first = measure("maze", "classic", "exact", 6.0, 0)
    again = measure("maze", "classic", "exact", 6.0, 0)
    other_seed = measure("maze", "classic", "exact", 6.0, 1)
    assert len(first["fingerprint"]) == 12
    assert first["fingerprint"] == again["fingerprint"]
    assert other_seed["fingerprint"] != first["fingerprint"]
    assert first["simulated_s"] == again["simulated_s"] > 0.0
