"""planners carry what they are to their paper's method: 'original', 'variant' or '' (not stated)

Planners stored before say nothing (''); the service's start-up sync fills in the built-ins'.

Revision ID: 0006
Revises: 0005
"""

from __future__ import annotations

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0006"
down_revision: str | None = "0005"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    # A plain ADD COLUMN, not batch mode: SQLite would rebuild `planners`, which `jobs` references.
    op.add_column("planners", sa.Column("method", sa.String(length=16), nullable=False,
                                        server_default=sa.text("''")))


def downgrade() -> None:
    op.drop_column("planners", "method")
