"""Which tests are `slow`: `make test-fast` runs `pytest -m "not slow"`, `make test` runs all.

A test is slow when it takes more than a few seconds on a two-core machine: flights of tens of
simulated seconds, the service end to end, the fault and load tests, the sandbox's hostile
planners, the wheel's install. Tests in files of their own mark themselves
(`@pytest.mark.slow`); the long ones of the other folders are listed here by node id, so that
their files stay as they are, and so are the PostgreSQL variants of the database tests (their
SQLite twins stay in the fast run).

An entry is a test file, or a test (every parametrization of it). Measure with
`pytest --durations=40` before adding one; a renamed or removed test leaves its entry inert.
"""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import pytest

import flybo  # noqa: F401  first: it pins the CPU kernels before NumPy loads (flybo.cpu_kernels)

SLOW = (
    # Whole files: each test starts services, fails them or floods them.
    "tests/faults/",
    "tests/load/",
    "tests/security/test_schemathesis.py",
    "tests/server/test_end_to_end.py",
    "tests/sandbox/test_hostile.py",
    "tests/sandbox/test_builtin_in_sandbox.py",
    # Ground truth and generation of every built-in area.
    "tests/areas/test_builtin_areas.py::test_ground_truth_reaches_every_level",
    "tests/areas/test_builtin_areas.py::test_every_level_is_reachable_by_the_vehicle",
    "tests/areas/test_builtin_areas.py::test_generation_is_deterministic_per_seed",
    "tests/areas/test_builtin_areas.py::test_every_component_is_closed_and_consistently_wound",
    "tests/areas/test_ground_truth.py::test_maze_observable_volume_and_speed",
    # Flights.
    "tests/planners/test_conformance.py::test_short_exact_flight_in_the_maze",
    "tests/planners/test_astar.py::test_astar_length_equals_dijkstra",
    "tests/sim/test_episode.py::test_same_seed_without_time_charge_is_repeatable",
    "tests/sim/test_episode.py::test_recording_holds_the_flight",
    # The service with uploads, sandboxed dry runs and real runs.
    "tests/server/test_planner_upload.py::test_upload_versions_and_a_run_to_the_leaderboard",
    "tests/server/test_groups.py::test_flybo_benchmark_against_a_real_service",
    "tests/server/test_groups.py::test_bad_groups_are_refused_and_nothing_is_stored",
    "tests/security/test_hostile_uploads.py::test_streamed_gigabyte_body_is_cut_off",
    "tests/security/test_hostile_uploads.py::test_ten_million_faces",
    "tests/security/test_hostile_uploads.py::test_planner_zip_bomb",
    # Seconds each of computing in the fast loop's slowest modules.
    "tests/test_report.py::test_report_from_a_real_app",
    "tests/test_cli.py::test_areas_build_fills_the_cache",
    "tests/areas/test_stats_thumbnail.py::test_cache_file_is_named_by_generator_version_and_seed",
    "tests/sim/test_occupancy.py::test_dda_matches_reference_on_random_rays",
    "tests/planners/test_gain.py::test_gain_estimates_the_visible_unknown_volume",
)


def _is_slow(item: pytest.Item) -> bool:
    node = item.nodeid
    test = node.split("[", 1)[0]
    for entry in SLOW:
        if entry.endswith("/") and node.startswith(entry):
            return True
        if test == entry or test.startswith(entry + "::") or node.startswith(entry + "::"):
            return True
    callspec = getattr(item, "callspec", None)
    return callspec is not None and callspec.params.get("database_url") == "postgresql"


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    for item in items:
        if _is_slow(item):
            item.add_marker(pytest.mark.slow)


@pytest.fixture(scope="module")
def playwright_driver() -> Iterator[Any]:
    """The Playwright driver of one test module. Its sync API keeps an event loop running in
    the process while it is open: a second driver refuses to start, and so does any
    `asyncio.run` of a later test in the process, so it is closed after the module's tests."""
    from playwright.sync_api import sync_playwright

    with sync_playwright() as driver:
        yield driver
