"""held-out split: areas carry their split and held-out generation; the generations table

Areas stored before are public (`split = 'public'`) and have no generation.

Revision ID: 0005
Revises: 0004
"""

from __future__ import annotations

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0005"
down_revision: str | None = "0004"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    # Plain ADD COLUMNs, not batch mode: SQLite would rebuild `areas`, which `runs` references.
    op.add_column("areas", sa.Column("split", sa.String(length=16), nullable=False,
                                     server_default=sa.text("'public'")))
    op.add_column("areas", sa.Column("heldout_generation", sa.Integer(), nullable=True))
    op.create_index("ix_areas_split", "areas", ["split"])
    op.create_table(
        "heldout_generations",
        sa.Column("id", sa.Integer(), primary_key=True),
        sa.Column("note", sa.Text(), nullable=False),
        sa.Column("created_at", sa.DateTime(timezone=True), nullable=False),
    )


def downgrade() -> None:
    op.drop_table("heldout_generations")
    op.drop_index("ix_areas_split", table_name="areas")
    op.drop_column("areas", "heldout_generation")
    op.drop_column("areas", "split")
