"""recipes: named inspection configurations, the active one per cell, the recipe of each
inspection

Revision ID: 0014
Revises: 0013
Create Date: 2026-12-07 01:15:00

``recipes`` holds a cell's named configurations (options, models in play, bins) with the
number a PLC selects one by; ``recipe_selections`` the active one (one row per cell);
``inspections.recipe_id`` / ``recipe_name`` the recipe each inspection ran under (none for
the rows stored before).  The audit trail records recipe changes (kind ``recipe``).
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

from backend.db.types import UTCDateTime

revision = "0014"
down_revision = "0013"
branch_labels = None
depends_on = None


_KINDS_BEFORE = (
    "kind IN ('threshold', 'model', 'view', 'negative', 'calibration', 'user', 'token', 'estop')"
)
_KINDS_AFTER = (
    "kind IN ('threshold', 'model', 'view', 'negative', 'calibration', 'user', 'token', "
    "'estop', 'recipe')"
)


def _audit_kinds(check: str) -> None:
    with op.batch_alter_table("audit_log") as batch:
        batch.drop_constraint(op.f("ck_audit_log_kind"), type_="check")
        batch.create_check_constraint(op.f("ck_audit_log_kind"), check)


def upgrade() -> None:
    _audit_kinds(_KINDS_AFTER)
    op.create_table(
        "recipes",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("cell_id", sa.Integer(), nullable=False),
        sa.Column("name", sa.String(length=64), nullable=False),
        sa.Column("number", sa.Integer(), nullable=False),
        sa.Column("description", sa.Text(), nullable=False),
        sa.Column("options", sa.JSON(), nullable=False),
        sa.Column("models", sa.JSON(), nullable=False),
        sa.Column("bins", sa.JSON(), nullable=False),
        sa.Column("created_at", UTCDateTime(), nullable=False),
        sa.Column("updated_at", UTCDateTime(), nullable=False),
        sa.CheckConstraint("number >= 1 AND number <= 9999", name=op.f("ck_recipes_number_range")),
        sa.ForeignKeyConstraint(
            ["cell_id"], ["cells.id"], name=op.f("fk_recipes_cell_id_cells"), ondelete="CASCADE"
        ),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_recipes")),
        sa.UniqueConstraint("cell_id", "name", name="uq_recipes_cell_name"),
        sa.UniqueConstraint("cell_id", "number", name="uq_recipes_cell_number"),
    )
    op.create_index(op.f("ix_recipes_cell_id"), "recipes", ["cell_id"])
    op.create_table(
        "recipe_selections",
        sa.Column("cell_id", sa.Integer(), nullable=False),
        sa.Column("recipe_id", sa.Integer(), nullable=False),
        sa.Column("activated_at", UTCDateTime(), nullable=False),
        sa.Column("activated_by", sa.String(length=64), nullable=False),
        sa.ForeignKeyConstraint(
            ["cell_id"], ["cells.id"], name=op.f("fk_recipe_selections_cell_id_cells"),
            ondelete="CASCADE",
        ),
        sa.ForeignKeyConstraint(
            ["recipe_id"], ["recipes.id"], name=op.f("fk_recipe_selections_recipe_id_recipes"),
            ondelete="CASCADE",
        ),
        sa.PrimaryKeyConstraint("cell_id", name=op.f("pk_recipe_selections")),
    )  # fmt: skip
    with op.batch_alter_table("inspections") as batch:
        batch.add_column(sa.Column("recipe_id", sa.Integer(), nullable=True))
        batch.add_column(sa.Column("recipe_name", sa.String(length=64), nullable=True))


def downgrade() -> None:
    with op.batch_alter_table("inspections") as batch:
        batch.drop_column("recipe_name")
        batch.drop_column("recipe_id")
    op.drop_table("recipe_selections")
    op.drop_index(op.f("ix_recipes_cell_id"), table_name="recipes")
    op.drop_table("recipes")
    op.execute("DELETE FROM audit_log WHERE kind = 'recipe'")
    _audit_kinds(_KINDS_BEFORE)
