"""inspection results: model name, policy, reason, stage durations, scores, pose, pick, truth

Revision ID: 0004
Revises: 0003
Create Date: 2026-12-02 00:05:00

Inspections through the product (issue 14, parts 3 to 6): each inspection row keeps the
recognised model's name, the policy, the reason of the decision, the seconds per stage, the
fused scores, the pose details, the pick outcome and, in the simulator, the truth beside the
result for evaluation.
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = "0004"
down_revision = "0003"
branch_labels = None
depends_on = None


def upgrade() -> None:
    with op.batch_alter_table("inspections", schema=None) as batch_op:
        batch_op.add_column(sa.Column("model_name", sa.String(length=64), nullable=True))
        batch_op.add_column(
            sa.Column("policy", sa.String(length=16), server_default="two-views", nullable=False)
        )
        batch_op.add_column(sa.Column("reason", sa.Text(), server_default="", nullable=False))
        batch_op.add_column(sa.Column("durations", sa.JSON(), nullable=True))
        batch_op.add_column(sa.Column("scores", sa.JSON(), nullable=True))
        batch_op.add_column(sa.Column("pose", sa.JSON(), nullable=True))
        batch_op.add_column(sa.Column("pick", sa.JSON(), nullable=True))
        batch_op.add_column(sa.Column("truth", sa.JSON(), nullable=True))
        batch_op.create_index(batch_op.f("ix_inspections_policy"), ["policy"], unique=False)


def downgrade() -> None:
    with op.batch_alter_table("inspections", schema=None) as batch_op:
        batch_op.drop_index(batch_op.f("ix_inspections_policy"))
        for name in ("truth", "pick", "pose", "scores", "durations", "reason", "policy"):
            batch_op.drop_column(name)
        batch_op.drop_column("model_name")
