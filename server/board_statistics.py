"""Confidence intervals and tie groups of the leaderboard (`docs/statistics.md`).

Every mean over runs carries a 95 % percentile-bootstrap interval: the runs of a cell (planner,
area) are resampled with replacement `RESAMPLES` times, each resample's mean is taken, and the
2.5th and 97.5th percentiles of those means bound the interval. The resampling is seeded by the
cell's planner and area (`SEED`), so a board is the same on every machine and whatever else it
holds. Runs where a metric is undefined are left out of its mean and of its resamples.

The means over areas (mean coverage, F-score, their mean ranks) resample each area's runs
independently and average the areas' resampled means, or the ranks those means get among the
planners of the area within the same resample.

Tie groups: planners are ordered by the point value; walking down that order, a planner joins
the group of the one above it when its interval overlaps the interval of that group's first
(best) planner, else it starts a new group. A group shares the rank of its first planner
(competition ranking: 1, 1, 3).
"""

from __future__ import annotations

import hashlib
from collections import defaultdict
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from server.schemas import (
    Interval,
    LeaderboardEntry,
    LeaderboardPlanner,
    Spread,
    StatisticsInfo,
)

RESAMPLES = 2000
CONFIDENCE = 0.95
SEED = 20261202
_TAILS = (50 * (1 - CONFIDENCE), 100 - 50 * (1 - CONFIDENCE))  # percentiles: 2.5, 97.5
INFO = StatisticsInfo(
    method="percentile bootstrap of the mean over runs", confidence=CONFIDENCE,
    resamples=RESAMPLES, seed=SEED,
    tie_rule="ordered by the point value, a planner shares the rank of the group above it "
             "when its interval overlaps that of the group's best planner (docs/statistics.md)")

Floats = npt.NDArray[np.float64]
# The columns of a cell (`describe`) the means over areas and the ranks are made of.
COVERAGE, RELATIVE, FSCORE = "coverage", "relative_coverage", "fscore"


def _rng(*names: str) -> np.random.Generator:
    digest = hashlib.blake2b("\x00".join(names).encode("utf-8"), digest_size=8).digest()
    return np.random.default_rng([SEED, int.from_bytes(digest, "little")])


def _percentiles(samples: Floats) -> Floats:
    """The `_TAILS` percentiles along the last axis, as `np.percentile`'s default (linear)
    method gives them, at a fraction of its overhead: shape (..., 2)."""
    last = samples.shape[-1] - 1
    spots = []
    for tail in _TAILS:
        at = last * tail / 100.0
        below = int(np.floor(at))
        spots.append((below, min(below + 1, last), at - below))
    # A partial sort that puts only the four order statistics in place: linear time.
    ordered = np.partition(samples, sorted({k for b, a, _ in spots for k in (b, a)}), axis=-1)
    return np.stack([ordered[..., b] * (1.0 - share) + ordered[..., a] * share
                     for b, a, share in spots], axis=-1)


def _interval(samples: Floats) -> tuple[float, float]:
    low, high = _percentiles(samples)
    return float(low), float(high)


def _weights(rng: np.random.Generator, n: int) -> Floats:
    """Each resample as weights on the `n` runs (how often it drew each, over n), shape
    (n, RESAMPLES): values @ weights are the resamples' means."""
    drawn = rng.integers(0, n, size=(RESAMPLES, n))
    # Each resample's draws counted per run, all resamples in one bincount.
    flat = (drawn + np.arange(RESAMPLES)[:, None] * n).ravel()
    counts = np.bincount(flat, minlength=RESAMPLES * n).reshape(RESAMPLES, n)
    return counts.T / n


@dataclass
class Cell:
    """One planner's resampled means on one area, by metric (`RESAMPLES` values each)."""

    samples: dict[str, Floats]


def describe(planner: str, area: str,
             columns: dict[str, Sequence[float | None]]) -> tuple[dict[str, Spread], Cell]:
    """Mean, min, max and the bootstrap interval of each column's runs; the runs of the cell
    are resampled once, the same resamples serving every column whose runs are all defined."""
    n = max((len(v) for v in columns.values()), default=0)
    spreads: dict[str, Spread] = {}
    samples: dict[str, Floats] = {}
    full = [k for k, v in columns.items() if len(v) == n and all(x is not None for x in v)]
    if full and n:
        matrix = np.array([columns[k] for k in full], dtype=np.float64)  # (metrics, runs)
        means = matrix @ _weights(_rng(planner, area), n)  # (metrics, resamples)
        lows, highs = _percentiles(means).T
        for i, key in enumerate(full):
            row = matrix[i]
            samples[key] = means[i]
            spreads[key] = _spread(row, float(lows[i]), float(highs[i]))
    for key, values in columns.items():
        if key in spreads:
            continue
        finite = np.array([v for v in values if v is not None], dtype=np.float64)
        if not len(finite):
            spreads[key] = Spread(mean=None, min=None, max=None)
            continue
        samples[key] = finite @ _weights(_rng(planner, area, key), len(finite))
        spreads[key] = _spread(finite, *_interval(samples[key]))
    return spreads, Cell(samples)


def _spread(values: Floats, low: float, high: float) -> Spread:
    """A mean's resamples never leave the runs' range but by rounding: kept within it."""
    smallest, largest = float(values.min()), float(values.max())
    return Spread(mean=float(values.mean()), min=smallest, max=largest,
                  ci_low=min(max(low, smallest), largest),
                  ci_high=max(min(high, largest), smallest))


def spread_interval(s: Spread) -> tuple[float, float] | None:
    return None if s.ci_low is None or s.ci_high is None else (s.ci_low, s.ci_high)


def overlaps(a: tuple[float, float] | None, b: tuple[float, float] | None) -> bool:
    """Whether two intervals share a point; a missing interval is told apart from none."""
    if a is None or b is None:
        return False
    return a[0] <= b[1] and b[0] <= a[1]


def tie_ranks(order: Sequence[str],
              intervals: dict[str, tuple[float, float] | None]) -> dict[str, int]:
    """Competition ranks of `order` (best first) with tie groups (see the module's rule)."""
    out: dict[str, int] = {}
    leader: str | None = None
    for position, name in enumerate(order, start=1):
        if leader is not None and overlaps(intervals[leader], intervals[name]):
            out[name] = out[leader]
        else:
            leader = name
            out[name] = position
    return out


def mean_interval(parts: Sequence[Floats]) -> Interval | None:
    """The interval of the mean over areas, from each area's resampled means."""
    if not parts:
        return None
    low, high = _interval(np.mean(np.stack(parts), axis=0))
    return Interval(low=low, high=high)


def resampled_ranks(cells: dict[str, Floats]) -> dict[str, Floats]:
    """Within each resample, the rank of each planner's mean among those of one area (1 for
    the highest, ties sharing the mean of their positions), as the point ranks are made."""
    names = list(cells)
    if not names:
        return {}
    values = np.stack([cells[n] for n in names])  # (planners, resamples)
    higher = (values[None, :, :] > values[:, None, :]).sum(axis=1)  # planners above each
    equal = (values[None, :, :] == values[:, None, :]).sum(axis=1)  # itself included
    ranks = higher + (equal + 1) / 2.0
    return {n: ranks[i] for i, n in enumerate(names)}


def rank_intervals(areas: dict[str, dict[str, Floats]],
                   planner_areas: dict[str, list[str]]) -> dict[str, Interval | None]:
    """Per planner, the interval of its mean rank over the areas it ran: `areas` maps an area
    to each planner's resampled means there."""
    ranked = {area: resampled_ranks(cells) for area, cells in areas.items()}
    return {planner: mean_interval([ranked[a][planner] for a in mine
                                    if planner in ranked.get(a, {})])
            for planner, mine in planner_areas.items()}


def _with(cells: list[Cell], key: str) -> list[Floats]:
    return [c.samples[key] for c in cells if key in c.samples]


def annotate(entries: list[LeaderboardEntry], overall: list[LeaderboardPlanner],
             cells: dict[tuple[str, str], Cell]) -> None:
    """Add the tie-group ranks of each area, the intervals of the means over areas and of the
    mean ranks, and the overall ranks by tie group (`overall` is in rank order already)."""
    by_area: dict[str, list[LeaderboardEntry]] = defaultdict(list)
    for e in entries:
        by_area[e.area].append(e)
    coverage: dict[str, dict[str, Floats]] = {}
    fscore: dict[str, dict[str, Floats]] = {}
    for area, here in by_area.items():
        ordered = sorted(here, key=lambda e: (-(e.coverage.mean or 0.0), e.planner))
        ranks = tie_ranks([e.planner for e in ordered],
                          {e.planner: spread_interval(e.coverage) for e in here})
        with_f = sorted((e for e in here if e.fscore.mean is not None),
                        key=lambda e: (-(e.fscore.mean or 0.0), e.planner))
        franks = tie_ranks([e.planner for e in with_f],
                           {e.planner: spread_interval(e.fscore) for e in with_f})
        for e in here:
            e.coverage_group_rank = ranks[e.planner]
            e.fscore_group_rank = franks.get(e.planner)
        coverage[area] = {e.planner: cells[(e.planner, area)].samples[COVERAGE] for e in here
                          if COVERAGE in cells[(e.planner, area)].samples}
        fscore[area] = {e.planner: cells[(e.planner, area)].samples[FSCORE] for e in with_f
                        if FSCORE in cells[(e.planner, area)].samples}
    mine: dict[str, list[str]] = defaultdict(list)
    for e in entries:
        mine[e.planner].append(e.area)
    coverage_ranks = rank_intervals(coverage, mine)
    fscore_ranks = rank_intervals(fscore, mine)
    for p in overall:
        own = [cells[(p.planner, a)] for a in mine[p.planner]]
        p.mean_coverage_ci = mean_interval(_with(own, COVERAGE))
        p.mean_relative_coverage_ci = mean_interval(_with(own, RELATIVE))
        p.mean_fscore_ci = mean_interval(_with(own, FSCORE))
        p.mean_coverage_rank_ci = coverage_ranks.get(p.planner)
        p.mean_fscore_rank_ci = fscore_ranks.get(p.planner) if p.mean_fscore_rank is not None \
            else None
    overall_ranks = tie_ranks([p.planner for p in overall], {
        p.planner: None if p.mean_coverage_rank_ci is None else
        (p.mean_coverage_rank_ci.low, p.mean_coverage_rank_ci.high) for p in overall})
    for p in overall:
        p.rank = overall_ranks[p.planner]
