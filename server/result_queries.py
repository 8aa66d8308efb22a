"""The one query under every ranked view: succeeded runs of a preset and benchmark version with
their result, job, planner and area joined (the leaderboard and the curves add their columns)."""

from __future__ import annotations

from typing import Any

from sqlalchemy import Select, select

from server.models import AreaRow, Job, PlannerRow, Run, RunResult, RunState


def succeeded_results(*columns: Any, preset: str, benchmark_version: str) -> Select[Any]:
    """`columns` of every succeeded run of `preset` made by `benchmark_version`; the caller
    may join more (a run's series) and filter further (a split, an area)."""
    return (
        select(*columns)
        .select_from(Run)
        .join(RunResult, RunResult.run_id == Run.id)
        .join(Job, Run.job_id == Job.id)
        .join(PlannerRow, Job.planner_id == PlannerRow.id)
        .join(AreaRow, Run.area_id == AreaRow.id)
        .where(Run.status == RunState.SUCCEEDED.value, Run.preset == preset,
               RunResult.benchmark_version == benchmark_version)
    )
