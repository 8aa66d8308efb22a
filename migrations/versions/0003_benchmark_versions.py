"""benchmark versions: each result names the benchmark version and the record it was made with

Results stored before read benchmark version 'legacy', without a record or a metrics block.

Revision ID: 0003
Revises: 0002
"""

from __future__ import annotations

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0003"
down_revision: str | None = "0002"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None

LEGACY_VERSION = "legacy"  # server.models.LEGACY_VERSION, fixed here as the revision ran


def upgrade() -> None:
    # The server default fills the rows already there; new rows must name their version, so
    # it goes again. Batch mode: SQLite cannot drop a column default in place.
    with op.batch_alter_table("run_results", schema=None) as batch_op:
        batch_op.add_column(sa.Column("benchmark_version", sa.String(length=64), nullable=False,
                                      server_default=LEGACY_VERSION))
        batch_op.add_column(sa.Column("record", sa.JSON(), nullable=True))
        batch_op.add_column(sa.Column("metrics", sa.JSON(), nullable=True))
        batch_op.create_index(batch_op.f("ix_run_results_benchmark_version"),
                              ["benchmark_version"], unique=False)
    with op.batch_alter_table("run_results", schema=None) as batch_op:
        batch_op.alter_column("benchmark_version", existing_type=sa.String(length=64),
                              existing_nullable=False, server_default=None)


def downgrade() -> None:
    with op.batch_alter_table("run_results", schema=None) as batch_op:
        batch_op.drop_index(batch_op.f("ix_run_results_benchmark_version"))
        batch_op.drop_column("metrics")
        batch_op.drop_column("record")
        batch_op.drop_column("benchmark_version")
