"""in-progress inspection markers and stored station backgrounds

Revision ID: 0009
Revises: 0006
Create Date: 2026-12-02 02:50:00

Issue 16, part 1: ``inspections_in_progress`` holds one row per inspection that has started
and not yet stored its result (deleted in the result's transaction), so a process killed
mid-inspection finds it at start-up and marks it interrupted; ``station_backgrounds`` keeps
the empty-belt backgrounds grabbed by teaches, so a restarted cell inspects without a teach.
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

from backend.db.types import UTCDateTime

revision = "0009"
down_revision = "0008"
branch_labels = None
depends_on = None


def upgrade() -> None:
    op.create_table(
        "inspections_in_progress",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("cell_id", sa.Integer(), nullable=False),
        sa.Column("started_at", UTCDateTime(), nullable=False),
        sa.Column("policy", sa.String(length=16), nullable=False),
        sa.Column("owner", sa.String(length=128), nullable=False),
        sa.ForeignKeyConstraint(
            ["cell_id"],
            ["cells.id"],
            name=op.f("fk_inspections_in_progress_cell_id_cells"),
            ondelete="CASCADE",
        ),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_inspections_in_progress")),
    )
    op.create_index(
        op.f("ix_inspections_in_progress_cell_id"), "inspections_in_progress", ["cell_id"]
    )
    op.create_table(
        "station_backgrounds",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("cell_id", sa.Integer(), nullable=False),
        sa.Column("shot_key", sa.JSON(), nullable=False),
        sa.Column("image_png", sa.LargeBinary(), nullable=False),
        sa.Column("taken_at", UTCDateTime(), nullable=False),
        sa.ForeignKeyConstraint(
            ["cell_id"],
            ["cells.id"],
            name=op.f("fk_station_backgrounds_cell_id_cells"),
            ondelete="CASCADE",
        ),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_station_backgrounds")),
    )
    op.create_index(op.f("ix_station_backgrounds_cell_id"), "station_backgrounds", ["cell_id"])


def downgrade() -> None:
    op.drop_index(op.f("ix_station_backgrounds_cell_id"), table_name="station_backgrounds")
    op.drop_table("station_backgrounds")
    op.drop_index(op.f("ix_inspections_in_progress_cell_id"), table_name="inspections_in_progress")
    op.drop_table("inspections_in_progress")
