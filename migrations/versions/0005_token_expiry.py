"""api tokens' expiry

Revision ID: 0005
Revises: 0004
Create Date: 2026-12-02 00:10:00

Security of a running cell (issue 16, part 3): an API token may carry an instant after
which it signs nobody in.  Existing tokens keep no expiry (NULL).
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

import backend.db.types

revision = "0005"
down_revision = "0004"
branch_labels = None
depends_on = None


def upgrade() -> None:
    with op.batch_alter_table("api_tokens", schema=None) as batch_op:
        batch_op.add_column(
            sa.Column("expires_at", backend.db.types.UTCDateTime(timezone=True), nullable=True)
        )


def downgrade() -> None:
    with op.batch_alter_table("api_tokens", schema=None) as batch_op:
        batch_op.drop_column("expires_at")
