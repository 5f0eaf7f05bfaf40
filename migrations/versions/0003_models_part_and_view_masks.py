"""object models' part; trained views' mask, thumbnail, size, yaw, roll, source, pose

Revision ID: 0003
Revises: 0002
Create Date: 2026-12-01 22:55:00

Teaching through the product (issue 14, part 1): each object model names the physical part
it is a sitting base of (sorting has one bin per part); each trained view keeps the object's
mask, a thumbnail, its size, the object yaw and camera roll it was taken at, where it came
from (teach, upload, import) and, when the arm took it, the joints and camera pose.
Existing models get their own name as part.
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = "0003"
down_revision = "0002"
branch_labels = None
depends_on = None


def upgrade() -> None:
    with op.batch_alter_table("object_models", schema=None) as batch_op:
        batch_op.add_column(
            sa.Column("part", sa.String(length=64), server_default="", nullable=False)
        )
        batch_op.create_index(batch_op.f("ix_object_models_part"), ["part"], unique=False)
    op.execute("UPDATE object_models SET part = name WHERE part = ''")

    with op.batch_alter_table("trained_views", schema=None) as batch_op:
        batch_op.add_column(sa.Column("mask_png", sa.LargeBinary(), nullable=True))
        batch_op.add_column(sa.Column("thumbnail_jpeg", sa.LargeBinary(), nullable=True))
        batch_op.add_column(sa.Column("width", sa.Integer(), server_default="0", nullable=False))
        batch_op.add_column(sa.Column("height", sa.Integer(), server_default="0", nullable=False))
        batch_op.add_column(sa.Column("yaw_rad", sa.Float(), server_default="0", nullable=False))
        batch_op.add_column(sa.Column("roll_rad", sa.Float(), server_default="0", nullable=False))
        batch_op.add_column(
            sa.Column("source", sa.String(length=16), server_default="upload", nullable=False)
        )
        batch_op.add_column(sa.Column("joints", sa.JSON(), nullable=True))
        batch_op.add_column(sa.Column("T_base_cam", sa.JSON(), nullable=True))
        batch_op.create_check_constraint("source", "source IN ('teach', 'upload', 'import')")


def downgrade() -> None:
    with op.batch_alter_table("trained_views", schema=None) as batch_op:
        batch_op.drop_constraint(batch_op.f("ck_trained_views_source"), type_="check")
        for col in (
            "T_base_cam",
            "joints",
            "source",
            "roll_rad",
            "yaw_rad",
            "height",
            "width",
            "thumbnail_jpeg",
            "mask_png",
        ):
            batch_op.drop_column(col)
    with op.batch_alter_table("object_models", schema=None) as batch_op:
        batch_op.drop_index(batch_op.f("ix_object_models_part"))
        batch_op.drop_column("part")
