"""in-progress job markers

Revision ID: 0012
Revises: 0011
Create Date: 2026-12-06 22:00:00

``jobs_in_progress`` holds one row per job that has started and not yet ended (deleted when
it ends), so a process killed during a job finds it at start-up and lists it as interrupted.
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

from backend.db.types import UTCDateTime

revision = "0012"
down_revision = "0011"
branch_labels = None
depends_on = None


def upgrade() -> None:
    op.create_table(
        "jobs_in_progress",
        sa.Column("id", sa.String(length=64), nullable=False),
        sa.Column("cell_id", sa.Integer(), nullable=False),
        sa.Column("kind", sa.String(length=64), nullable=False),
        sa.Column("started_at", UTCDateTime(), nullable=False),
        sa.Column("params", sa.JSON(), nullable=False),
        sa.Column("owner", sa.String(length=128), nullable=False),
        sa.ForeignKeyConstraint(
            ["cell_id"],
            ["cells.id"],
            name=op.f("fk_jobs_in_progress_cell_id_cells"),
            ondelete="CASCADE",
        ),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_jobs_in_progress")),
    )
    op.create_index(op.f("ix_jobs_in_progress_cell_id"), "jobs_in_progress", ["cell_id"])


def downgrade() -> None:
    op.drop_index(op.f("ix_jobs_in_progress_cell_id"), table_name="jobs_in_progress")
    op.drop_table("jobs_in_progress")
