"""calibration sample names

Revision ID: 0002
Revises: 0001
Create Date: 2026-11-22 02:47:25.975332

Each calibration sample keeps the name it was uploaded under (e.g. ``left04.jpg``), so
that reports can say which image was rejected and why.
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = "0002"
down_revision = "0001"
branch_labels = None
depends_on = None


def upgrade() -> None:
    with op.batch_alter_table("calibration_samples", schema=None) as batch_op:
        batch_op.add_column(
            sa.Column("name", sa.String(length=255), server_default="", nullable=False)
        )


def downgrade() -> None:
    with op.batch_alter_table("calibration_samples", schema=None) as batch_op:
        batch_op.drop_column("name")
