"""The leaderboard's bootstrap intervals and tie groups (`server.board_statistics`), alone and
in the boards the API serves."""

from __future__ import annotations

import numpy as np
import pytest
from sqlalchemy import select
from sqlalchemy.orm import Session, sessionmaker

from server.board_statistics import (
    RESAMPLES,
    describe,
    overlaps,
    resampled_ranks,
    tie_ranks,
)
from server.db import session_scope
from server.leaderboard import compute_leaderboard
from server.models import User
from server.security import create_token
from tests.web.stored import add_area, add_job, add_planner, add_run, current_version


def test_two_runs_bound_the_interval_by_themselves() -> None:
    # Resampled means of two runs are 0.6, 0.7 or 0.8 (probabilities 1/4, 1/2, 1/4): the 2.5th
    # and 97.5th percentiles are the runs themselves.
    spreads, cell = describe("p", "a", {"coverage": [0.8, 0.6]})
    s = spreads["coverage"]
    assert (s.mean, s.min, s.max) == pytest.approx((0.7, 0.6, 0.8))
    assert (s.ci_low, s.ci_high) == pytest.approx((0.6, 0.8))
    assert cell.samples["coverage"].shape == (RESAMPLES,)
    assert set(np.round(cell.samples["coverage"], 9)) == {0.6, 0.7, 0.8}


def test_one_run_has_a_zero_width_interval_and_missing_values_are_left_out() -> None:
    spreads, _ = describe("p", "a", {"fscore": [None, 0.4, None], "x": [None, None, None]})
    assert (spreads["fscore"].mean, spreads["fscore"].ci_low, spreads["fscore"].ci_high) == (
        0.4, 0.4, 0.4)
    assert spreads["x"].mean is None and spreads["x"].ci_low is None


def test_intervals_are_seeded_by_the_cell_and_shrink_with_runs() -> None:
    rng = np.random.default_rng(1)
    few = list(rng.normal(0.7, 0.05, 5))
    many = list(rng.normal(0.7, 0.05, 80))
    a, _ = describe("p", "a", {"coverage": few, "other": few})
    b, _ = describe("p", "a", {"other": few, "coverage": few})
    assert a["coverage"] == b["coverage"]  # the same cell, the same interval, in any order
    c, _ = describe("q", "a", {"coverage": few})
    assert c["coverage"] != a["coverage"]  # another cell resamples otherwise
    wide = a["coverage"].ci_high - a["coverage"].ci_low  # type: ignore[operator]
    big, _ = describe("p", "a", {"coverage": many})
    narrow = big["coverage"].ci_high - big["coverage"].ci_low  # type: ignore[operator]
    assert 0 < narrow < wide
    s = a["coverage"]
    assert s.min < s.ci_low < s.mean < s.ci_high < s.max  # type: ignore[operator]


def test_tie_groups_follow_the_leader_rule() -> None:
    intervals = {"a": (0.80, 0.90), "b": (0.75, 0.85), "c": (0.70, 0.78), "d": (0.60, 0.65),
                 "e": (0.60, 0.66)}
    # b overlaps a: shares 1. c overlaps b but not the group's leader a: 3. d and e overlap: 4.
    assert tie_ranks(["a", "b", "c", "d", "e"], intervals) == {
        "a": 1, "b": 1, "c": 3, "d": 4, "e": 4}
    assert overlaps((0, 1), (1, 2)) and not overlaps((0, 1), (1.01, 2))
    assert not overlaps(None, (0, 1))


def test_resampled_ranks_share_ties_as_the_point_ranks_do() -> None:
    ranks = resampled_ranks({"a": np.array([1.0, 2.0]), "b": np.array([1.0, 3.0]),
                             "c": np.array([0.0, 4.0])})
    assert ranks["a"].tolist() == [1.5, 3.0]
    assert ranks["b"].tolist() == [1.5, 2.0]
    assert ranks["c"].tolist() == [3.0, 1.0]


def test_the_board_carries_intervals_and_tie_groups(sessions: sessionmaker[Session]) -> None:
    """On MAZE: alpha 0.80-0.84 and beta 0.79-0.83 overlap; gamma 0.50-0.52 is apart. On
    HALL alpha leads clearly. Overall, alpha and beta share rank 1 only if their mean-rank
    intervals overlap: they do (beta beats alpha on MAZE in some resamples)."""
    with session_scope(sessions) as s:
        create_token(s, "alice", "secret")
        alice = s.scalars(select(User).where(User.name == "alice")).one()
        maze, hall = add_area(s, "maze"), add_area(s, "hall")
        for name, maze_cov, hall_cov in (("alpha", (0.80, 0.84, 0.82), (0.9, 0.91, 0.92)),
                                         ("beta", (0.83, 0.79, 0.81), (0.6, 0.62, 0.61)),
                                         ("gamma", (0.50, 0.52, 0.51), (0.3, 0.31, 0.32))):
            job = add_job(s, alice, add_planner(s, name))
            for seed, cov in enumerate(maze_cov):
                add_run(s, job, maze, seed, coverage=cov, fscore=cov / 2, volume=[0, 1, cov],
                        recall=[0.1])
            for seed, cov in enumerate(hall_cov):
                add_run(s, job, hall, seed, coverage=cov, fscore=None, volume=[0, 1, cov],
                        recall=[0.1])
    with sessions() as s:
        board = compute_leaderboard(s, "default", benchmark_version=current_version())
    assert board.statistics is not None and board.statistics.resamples == RESAMPLES
    maze_entries = {e.planner: e for e in board.entries if e.area == "maze"}
    assert {p: e.coverage_group_rank for p, e in maze_entries.items()} == {
        "alpha-v1": 1, "beta-v1": 1, "gamma-v1": 3}
    assert maze_entries["alpha-v1"].coverage_rank == 1.0  # the paper's, by the mean alone
    hall_entries = {e.planner: e for e in board.entries if e.area == "hall"}
    assert {p: e.coverage_group_rank for p, e in hall_entries.items()} == {
        "alpha-v1": 1, "beta-v1": 2, "gamma-v1": 3}
    assert all(e.fscore_group_rank is None for e in hall_entries.values())
    by = {p.planner: p for p in board.overall}
    alpha, beta, gamma = by["alpha-v1"], by["beta-v1"], by["gamma-v1"]
    assert alpha.mean_coverage_rank_ci is not None and beta.mean_coverage_rank_ci is not None
    assert alpha.mean_coverage_rank_ci.low == 1.0 and beta.mean_coverage_rank_ci.high == 2.0
    assert gamma.mean_coverage_rank_ci == type(gamma.mean_coverage_rank_ci)(low=3.0, high=3.0)
    assert (alpha.rank, beta.rank, gamma.rank) == (1, 1, 3)
    assert alpha.mean_coverage_ci is not None
    assert alpha.mean_coverage_ci.low < alpha.mean_coverage < alpha.mean_coverage_ci.high
    assert alpha.mean_fscore_rank_ci is not None  # from MAZE, its only area with F-scores
