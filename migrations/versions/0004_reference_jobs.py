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
    # A plain ADD COLUMN, not batch mode: SQLite would rebuild `jobs`, whose rows `runs`
    # references. The default stays (the model declares it too): it fills the rows already
    # there, and SQLite cannot drop a default without that rebuild.
    op.add_column("jobs", sa.Column("reference", sa.Boolean(), nullable=False,
                                    server_default=sa.text("false")))


def downgrade() -> None:
    op.drop_column("jobs", "reference")  # SQLite 3.35 and later drop a column in place
