"""job groups: a suite of jobs submitted together

Revision ID: 0002
Revises: 0001
"""

from __future__ import annotations

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0002"
down_revision: str | None = "0001"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    op.create_table(
        "job_groups",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("user_id", sa.Integer(), nullable=False),
        sa.Column("name", sa.String(length=128), nullable=False),
        sa.Column("preset", sa.String(length=32), nullable=False),
        sa.Column("runs_per_area", sa.Integer(), nullable=False),
        sa.Column("seconds", sa.Float(), nullable=True),
        sa.Column("time_scale", sa.Float(), nullable=True),
        sa.Column("idempotency_key", sa.String(length=128), nullable=True),
        sa.Column("request_hash", sa.String(length=64), nullable=False),
        sa.Column("created_at", sa.DateTime(timezone=True), nullable=False),
        sa.ForeignKeyConstraint(["user_id"], ["users.id"]),
        sa.PrimaryKeyConstraint("id"),
        sa.UniqueConstraint("user_id", "idempotency_key",
                            name="uq_job_groups_user_idempotency_key"),
    )
    with op.batch_alter_table("job_groups", schema=None) as batch_op:
        batch_op.create_index(batch_op.f("ix_job_groups_created_at"), ["created_at"],
                              unique=False)
        batch_op.create_index(batch_op.f("ix_job_groups_user_id"), ["user_id"], unique=False)

    # Batch mode: SQLite cannot add a foreign key to an existing table, so the table is copied.
    with op.batch_alter_table("jobs", schema=None) as batch_op:
        batch_op.add_column(sa.Column("group_id", sa.Integer(), nullable=True))
        batch_op.create_index(batch_op.f("ix_jobs_group_id"), ["group_id"], unique=False)
        batch_op.create_foreign_key("fk_jobs_group_id_job_groups", "job_groups", ["group_id"],
                                    ["id"])


def downgrade() -> None:
    with op.batch_alter_table("jobs", schema=None) as batch_op:
        batch_op.drop_constraint("fk_jobs_group_id_job_groups", type_="foreignkey")
        batch_op.drop_index(batch_op.f("ix_jobs_group_id"))
        batch_op.drop_column("group_id")

    with op.batch_alter_table("job_groups", schema=None) as batch_op:
        batch_op.drop_index(batch_op.f("ix_job_groups_user_id"))
        batch_op.drop_index(batch_op.f("ix_job_groups_created_at"))

    op.drop_table("job_groups")
