"""recognition of uploaded images: inspections.source, negative_images

Revision ID: 0013
Revises: 0012
Create Date: 2026-12-06 21:40:00

``inspections.source`` says where an inspection's images came from: ``cell`` (the arm's
camera; every row stored so far) or ``upload`` (an image sent to ``POST
/api/recognition/recognise`` with ``store=true``).  ``negative_images`` holds images of no
trained object, impostors for the automatic threshold; the audit trail records their
changes (kind ``negative``).
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

from backend.db.types import UTCDateTime

revision = "0013"
down_revision = "0012"
branch_labels = None
depends_on = None


_KINDS_BEFORE = "kind IN ('threshold', 'model', 'view', 'calibration', 'user', 'token', 'estop')"
_KINDS_AFTER = (
    "kind IN ('threshold', 'model', 'view', 'negative', 'calibration', 'user', 'token', 'estop')"
)


def _audit_kinds(check: str) -> None:
    with op.batch_alter_table("audit_log") as batch:
        batch.drop_constraint(op.f("ck_audit_log_kind"), type_="check")
        batch.create_check_constraint(op.f("ck_audit_log_kind"), check)


def upgrade() -> None:
    _audit_kinds(_KINDS_AFTER)
    with op.batch_alter_table("inspections") as batch:
        batch.add_column(
            sa.Column("source", sa.String(length=16), server_default="cell", nullable=False)
        )
    op.create_table(
        "negative_images",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("image_png", sa.LargeBinary(), nullable=False),
        sa.Column("width", sa.Integer(), nullable=False),
        sa.Column("height", sa.Integer(), nullable=False),
        sa.Column("source", sa.String(length=16), nullable=False),
        sa.Column("note", sa.String(length=200), nullable=False),
        sa.Column("created_at", UTCDateTime(), nullable=False),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_negative_images")),
    )


def downgrade() -> None:
    op.execute("DELETE FROM audit_log WHERE kind = 'negative'")
    _audit_kinds(_KINDS_BEFORE)
    op.drop_table("negative_images")
    with op.batch_alter_table("inspections") as batch:
        batch.drop_column("source")
