"""object models' height and grasp point

Revision ID: 0008
Revises: 0006
Create Date: 2026-12-02 03:05:00

Pick and sort (issue 14, part 5): what the pick needs of a model, stored with it so that the
decision and the pick never read the simulator's catalogue: the object's height above its
sitting base and the suction point on its upper surface (object frame, metres), and where
they came from (``measured`` at teach time or ``entered`` by an engineer).  All NULL for
existing models (the pick then uses the height measured at inspection time and the top
centre).
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = "0008"
down_revision = "0007"
branch_labels = None
depends_on = None


def upgrade() -> None:
    with op.batch_alter_table("object_models", schema=None) as batch_op:
        batch_op.add_column(sa.Column("height_m", sa.Float(), nullable=True))
        batch_op.add_column(sa.Column("grasp_x_m", sa.Float(), nullable=True))
        batch_op.add_column(sa.Column("grasp_y_m", sa.Float(), nullable=True))
        batch_op.add_column(sa.Column("grasp_z_m", sa.Float(), nullable=True))
        batch_op.add_column(
            sa.Column("geometry_source", sa.String(length=16), nullable=False, server_default="")
        )
        batch_op.create_check_constraint(
            op.f("ck_object_models_height_range"),
            "height_m IS NULL OR (height_m > 0 AND height_m <= 0.5)",
        )


def downgrade() -> None:
    with op.batch_alter_table("object_models", schema=None) as batch_op:
        batch_op.drop_constraint(op.f("ck_object_models_height_range"), type_="check")
        batch_op.drop_column("geometry_source")
        batch_op.drop_column("grasp_z_m")
        batch_op.drop_column("grasp_y_m")
        batch_op.drop_column("grasp_x_m")
        batch_op.drop_column("height_m")
