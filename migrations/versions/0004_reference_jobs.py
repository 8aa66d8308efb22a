"""reference jobs: jobs whose runs were loaded from a baseline dataset

Jobs stored before read `reference = false`.

Revision ID: 0004
Revises: 0003
"""

from __future__ import annotations

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0004"
down_revision: str | None = "0003"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    # The server default fills the rows already there; the model sets the value of new rows,
    # so it goes again (batch mode: SQLite cannot drop a column default in place).
    with op.batch_alter_table("jobs", schema=None) as batch_op:
        batch_op.add_column(sa.Column("reference", sa.Boolean(), nullable=False,
                                      server_default=sa.false()))
    with op.batch_alter_table("jobs", schema=None) as batch_op:
        batch_op.alter_column("reference", existing_type=sa.Boolean(), existing_nullable=False,
                              server_default=None)


def downgrade() -> None:
    with op.batch_alter_table("jobs", schema=None) as batch_op:
        batch_op.drop_column("reference")
