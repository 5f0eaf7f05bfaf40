"""Recipes (named inspection configurations of a cell) and each cell's active one."""

from __future__ import annotations

from datetime import datetime
from typing import Any

from sqlalchemy import JSON, CheckConstraint, ForeignKey, Integer, String, Text, UniqueConstraint
from sqlalchemy.orm import Mapped, mapped_column

from backend.db.models.base import Base
from backend.db.types import utcnow


class Recipe(Base):
    """A named inspection configuration of one cell (:mod:`backend.recipes`): the options a
    run takes from it, the models in play and their bins; a PLC selects it by ``number``."""

    __tablename__ = "recipes"

    id: Mapped[int] = mapped_column(primary_key=True)
    cell_id: Mapped[int] = mapped_column(ForeignKey("cells.id", ondelete="CASCADE"), index=True)
    name: Mapped[str] = mapped_column(String(64))
    #: 1..9999, unique per cell: what a PLC selects the recipe by.
    number: Mapped[int] = mapped_column(Integer)
    description: Mapped[str] = mapped_column(Text, default="")
    #: policy, max_views, sort, threshold (None: the cell's thresholds), belt_mode, speed,
    #: balance_light (:class:`backend.recipes.model.RecipeOptions`).
    options: Mapped[dict[str, Any]] = mapped_column(JSON, default=dict)
    #: Names of the models in play (empty: every trained model).
    models: Mapped[list[Any]] = mapped_column(JSON, default=list)
    #: Model name -> bin name (models not named keep their part's bin).
    bins: Mapped[dict[str, Any]] = mapped_column(JSON, default=dict)
    created_at: Mapped[datetime] = mapped_column(default=utcnow)
    updated_at: Mapped[datetime] = mapped_column(default=utcnow)

    __table_args__ = (
        UniqueConstraint("cell_id", "name", name="uq_recipes_cell_name"),
        UniqueConstraint("cell_id", "number", name="uq_recipes_cell_number"),
        CheckConstraint("number >= 1 AND number <= 9999", name="number_range"),
    )


class RecipeSelection(Base):
    """The active recipe of a cell: at most one row per cell (its primary key)."""

    __tablename__ = "recipe_selections"

    cell_id: Mapped[int] = mapped_column(
        ForeignKey("cells.id", ondelete="CASCADE"), primary_key=True
    )
    recipe_id: Mapped[int] = mapped_column(ForeignKey("recipes.id", ondelete="CASCADE"))
    activated_at: Mapped[datetime] = mapped_column(default=utcnow)
    #: Who selected it (user name, ``cli``, or a PLC link's name).
    activated_by: Mapped[str] = mapped_column(String(64), default="")
