"""audit trail: emergency stops (kind 'estop')

Revision ID: 0011
Revises: 0010
Create Date: 2026-12-06 22:00:00

Every press and reset of the cell-wide emergency stop is recorded in the audit trail (who,
where it was pressed, what was halted), written after the stop itself, so the check
constraint on ``audit_log.kind`` admits ``estop``.
"""

from __future__ import annotations

from alembic import op

revision = "0011"
down_revision = "0010"
branch_labels = None
depends_on = None

_OLD = "kind IN ('threshold', 'model', 'view', 'calibration', 'user', 'token')"
_NEW = "kind IN ('threshold', 'model', 'view', 'calibration', 'user', 'token', 'estop')"


def _replace(check: str) -> None:
    # SQLite cannot alter a constraint: the batch mode copies the table with the new one.
    with op.batch_alter_table("audit_log", schema=None) as batch_op:
        batch_op.drop_constraint(batch_op.f("ck_audit_log_kind"), type_="check")
        batch_op.create_check_constraint(batch_op.f("ck_audit_log_kind"), check)


def upgrade() -> None:
    _replace(_NEW)


def downgrade() -> None:
    op.execute("DELETE FROM audit_log WHERE kind = 'estop'")
    _replace(_OLD)
