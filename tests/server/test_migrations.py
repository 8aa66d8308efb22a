"""The Alembic revisions create exactly the tables the models describe, on both databases."""

from __future__ import annotations

from datetime import UTC, datetime

from alembic import command
from alembic.autogenerate import compare_metadata
from alembic.migration import MigrationContext
from sqlalchemy import func, inspect, select, text
from sqlalchemy.orm import Session

from server.db import make_engine
from server.migrate import alembic_config, upgrade
from server.models import LEGACY_VERSION, Base, Job, Run, RunResult


def test_migrations_match_the_models(database_url: str) -> None:
    engine = make_engine(database_url)
    upgrade(engine)
    upgrade(engine)  # a second start-up finds nothing to do
    with engine.connect() as conn:
        context = MigrationContext.configure(conn, opts={"compare_type": True,
                                                         "compare_server_default": True})
        assert compare_metadata(context, Base.metadata) == []
        tables = set(inspect(conn).get_table_names())
    assert set(Base.metadata.tables) <= tables
    engine.dispose()


def test_downgrade_removes_every_table(database_url: str) -> None:
    engine = make_engine(database_url)
    upgrade(engine)
    cfg = alembic_config(database_url)
    command.downgrade(cfg, "base")
    with engine.connect() as conn:
        assert set(inspect(conn).get_table_names()) <= {"alembic_version"}
    engine.dispose()


def test_results_stored_before_versions_read_legacy(database_url: str) -> None:
    """A database at 0002 holding a finished run keeps it through 0003, filed under the
    benchmark version 'legacy' without a record or a metrics block; a new row must name its
    version (the default only filled the old rows)."""
    engine = make_engine(database_url)
    command.upgrade(alembic_config(database_url), "0002")
    now = datetime.now(UTC)
    with engine.begin() as conn:
        conn.execute(text("INSERT INTO users (id, name, is_admin, created_at) "
                          "VALUES (1, 'old', false, :now)"), {"now": now})
        conn.execute(text(
            "INSERT INTO planners (id, name, version, builtin, description, reference, "
            "code_hash, config, created_at) VALUES (1, 'classic', 1, true, '', '', '', '{}', "
            ":now)"), {"now": now})
        conn.execute(text(
            "INSERT INTO areas (id, name, builtin, content_hash, plateau_s, voxel_size, stats, "
            "created_at) VALUES (1, 'maze', true, 'h', 700, 0.1, '{}', :now)"), {"now": now})
        conn.execute(text(
            "INSERT INTO jobs (id, user_id, planner_id, preset, runs_per_area, request_hash, "
            "created_at) VALUES (1, 1, 1, 'default', 2, 'r', :now)"), {"now": now})
        for run_id in (1, 2):
            conn.execute(text(
                "INSERT INTO runs (id, job_id, area_id, seed, preset, seconds, status, attempts,"
                " progress, sim_time_s, cancel_requested, log_tail) VALUES (:id, 1, 1, :id, "
                "'default', 60, 'succeeded', 1, 1, 60, false, '')"), {"id": run_id})
            conn.execute(text(
                "INSERT INTO run_results (run_id, outcome, reason, simulated_until_s, "
                "explored_volume_m3, volume_at_plateau_m3, observable_volume_m3, coverage, "
                "volumetric_efficiency, collisions, path_length_m, iterations, wall_seconds) "
                "VALUES (:id, 'succeeded', 'time limit reached', 60, 50, 40 + :id, 100, 0.5, "
                "0.8, 0, 12.5, 7, 3)"), {"id": run_id})
    upgrade(engine)
    with Session(engine) as session:
        rows = session.scalars(select(RunResult).order_by(RunResult.run_id)).all()
        assert [(r.run_id, r.benchmark_version, r.record, r.metrics) for r in rows] == [
            (1, LEGACY_VERSION, None, None), (2, LEGACY_VERSION, None, None)]
        assert [r.volume_at_plateau_m3 for r in rows] == [41.0, 42.0]  # nothing else changed
        assert session.scalar(select(func.count()).select_from(Run)) == 2
        # Revision 0004: the jobs stored before are no reference results.
        assert session.scalars(select(Job.reference)).all() == [False]
    with engine.connect() as conn:
        column = next(c for c in inspect(conn).get_columns("run_results")
                      if c["name"] == "benchmark_version")
        assert column["default"] is None and not column["nullable"]
    engine.dispose()


def test_areas_stored_before_the_split_are_public(database_url: str) -> None:
    """A database at 0004 keeps its areas through 0005 as public ones, without a held-out
    generation; the generations table starts empty (generation 1 is current)."""
    from server.heldout import current_generation
    from server.models import AreaRow, HeldoutGeneration

    engine = make_engine(database_url)
    command.upgrade(alembic_config(database_url), "0004")
    with engine.begin() as conn:
        conn.execute(text(
            "INSERT INTO areas (id, name, builtin, content_hash, plateau_s, voxel_size, stats, "
            "created_at) VALUES (1, 'maze', true, 'h', 700, 0.1, '{}', :now)"),
            {"now": datetime.now(UTC)})
    upgrade(engine)
    with Session(engine) as session:
        area = session.scalars(select(AreaRow)).one()
        assert (area.split, area.heldout_generation, area.heldout) == ("public", None, False)
        assert session.scalar(select(func.count()).select_from(HeldoutGeneration)) == 0
        assert current_generation(session) == 1
    engine.dispose()


def test_planners_stored_before_their_method_say_nothing(database_url: str) -> None:
    """A database at 0005 keeps its planners through 0006 with the method not stated; the
    start-up sync then marks the built-ins as the registry does."""
    from planners.registry import spec
    from server.catalog import sync_builtin_planners
    from server.models import PlannerRow

    engine = make_engine(database_url)
    command.upgrade(alembic_config(database_url), "0005")
    with engine.begin() as conn:
        conn.execute(text(
            "INSERT INTO planners (id, name, version, builtin, description, reference, "
            "code_hash, config, created_at) VALUES (1, 'nbvp', 1, true, '', '', '', '{}', :now),"
            " (2, 'mine', 1, false, '', '', '', '{}', :now)"), {"now": datetime.now(UTC)})
    upgrade(engine)
    with Session(engine) as session:
        assert session.scalars(select(PlannerRow.method).order_by(PlannerRow.id)).all() == [
            "", ""]
        sync_builtin_planners(session)
        session.commit()
        method = {row.key: row.method for row in session.scalars(select(PlannerRow))}
    assert method["nbvp-v1"] == spec("nbvp-v1").method == "variant"
    assert method["nbvp-v2"] == "original"
    assert method["mine-v1"] == ""  # an uploaded planner says nothing
    engine.dispose()
