"""audit trail: the audit_log table

Revision ID: 0006
Revises: 0004
Create Date: 2026-12-02 00:10:00

Issue 15, part 5: every change of a threshold, object model, trained view, active
calibration, user or token is recorded with who, when, old and new value and reason.
``down_revision`` is the head of ``integ`` when this was written (0004); if 0005 lands
first, re-chain it onto it.
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

from backend.db.types import UTCDateTime

revision = "0006"
down_revision = "0004"
branch_labels = None
depends_on = None


def upgrade() -> None:
    op.create_table(
        "audit_log",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("at", UTCDateTime(), nullable=False),
        sa.Column("actor", sa.String(length=64), nullable=False),
        sa.Column("actor_role", sa.String(length=16), nullable=False),
        sa.Column("kind", sa.String(length=16), nullable=False),
        sa.Column("entity_id", sa.String(length=64), nullable=False),
        sa.Column("action", sa.String(length=32), nullable=False),
        sa.Column("old", sa.JSON(), nullable=True),
        sa.Column("new", sa.JSON(), nullable=True),
        sa.Column("reason", sa.Text(), nullable=False),
        sa.CheckConstraint(
            "kind IN ('threshold', 'model', 'view', 'calibration', 'user', 'token')",
            name=op.f("ck_audit_log_kind"),
        ),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_audit_log")),
    )
    op.create_index(op.f("ix_audit_log_at"), "audit_log", ["at"], unique=False)
    op.create_index(op.f("ix_audit_log_actor"), "audit_log", ["actor"], unique=False)
    op.create_index("ix_audit_log_kind_entity", "audit_log", ["kind", "entity_id"], unique=False)


def downgrade() -> None:
    op.drop_index("ix_audit_log_kind_entity", table_name="audit_log")
    op.drop_index(op.f("ix_audit_log_actor"), table_name="audit_log")
    op.drop_index(op.f("ix_audit_log_at"), table_name="audit_log")
    op.drop_table("audit_log")
