"""reports: inspection_scenes (3D scene recordings) and the indexes of the reports

Revision ID: 0007
Revises: 0006
Create Date: 2026-12-02 03:00:00

Issue 15, parts 3, 4 and 6: the viser scene recorded during an inspection, one row per
inspection; indexes that keep the report queries within 200 ms over 100,000 inspections
(``benchmarks/reports.py``).
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

from backend.db.types import UTCDateTime

revision = "0007"
down_revision = "0006"
branch_labels = None
depends_on = None


def upgrade() -> None:
    op.create_table(
        "inspection_scenes",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("inspection_id", sa.Integer(), nullable=False),
        sa.Column("scene", sa.LargeBinary(), nullable=False),
        sa.Column("size_bytes", sa.Integer(), nullable=False),
        sa.Column("created_at", UTCDateTime(), nullable=False),
        sa.ForeignKeyConstraint(
            ["inspection_id"],
            ["inspections.id"],
            name=op.f("fk_inspection_scenes_inspection_id_inspections"),
            ondelete="CASCADE",
        ),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_inspection_scenes")),
        sa.UniqueConstraint("inspection_id", name=op.f("uq_inspection_scenes_inspection_id")),
    )


def downgrade() -> None:
    op.drop_table("inspection_scenes")
