"""The data of `flybo report`, read from a service's API (`/areas`, `/leaderboard`, `/curves`)
through any `httpx.Client`, a test's `TestClient` included. A report is of one benchmark version
(the service's current one unless asked for another), as the leaderboard is."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import httpx

from server.baseline_format import SuiteEntry
from server.schemas import AreaOut, Curves, Leaderboard

CURVE_POINTS = 1000  # per curve: plenty for a printed figure, small to fetch


class ReportError(RuntimeError):
    """The service could not be read."""


@dataclass(frozen=True)
class ReportData:
    """What the report is made of: the leaderboard of one preset and benchmark version, the
    curves of each area that has results, and every area's statistics."""

    preset: str
    board: Leaderboard
    areas: list[AreaOut]
    curves: dict[str, Curves] = field(default_factory=dict)
    source: str = ""
    # A report of a baseline dataset: what its whole suite took (`docs/baselines.md`), and how
    # many of its runs are of the reported preset.
    suite: SuiteEntry | None = None
    suite_runs: int | None = None

    @property
    def benchmark_version(self) -> str:
        """The one benchmark version whose results the report shows."""
        return self.board.benchmark_version


def _get(client: httpx.Client, path: str, params: dict[str, Any] | None = None) -> Any:
    try:
        response = client.get(path, params=params)
    except httpx.HTTPError as exc:
        raise ReportError(f"cannot reach the service: {exc}") from None
    if response.status_code != 200:
        try:
            detail = str(response.json().get("detail", response.text))
        except ValueError:
            detail = response.text
        raise ReportError(f"GET {path} answered {response.status_code}: {detail[:500]}")
    return response.json()


def fetch_report_data(client: httpx.Client, preset: str = "default",
                      benchmark_version: str | None = None) -> ReportData:
    """Everything the report needs, from the API under `/api/v1` of `client`'s base URL: of
    `benchmark_version`, or of the service's current one."""
    params = {"preset": preset}
    if benchmark_version:
        params["benchmark_version"] = benchmark_version
    board = Leaderboard.model_validate(_get(client, "/api/v1/leaderboard", params))
    areas = [AreaOut.model_validate(a) for a in _get(client, "/api/v1/areas")]
    # The board's version, also when it was the default: the curves are of the same runs.
    curves = {
        area: Curves.model_validate(_get(client, "/api/v1/curves", {
            "area": area, "preset": preset, "benchmark_version": board.benchmark_version,
            "max_points": CURVE_POINTS}))
        for area in board.areas}
    return ReportData(preset=preset, board=board, areas=areas, curves=curves,
                      source=str(client.base_url))
