"""The PLC links' one seam to recipes: which recipe is active, selecting one by number, and
the inspection options a trigger or a run uses.

Recipes live in ``backend.recipes.service`` (``active_recipe(rt)``, ``activate_number(rt,
number, *, actor)``, ``options_for(recipe, overrides)``).  When that module is not present
the links still trigger and run, with the default :class:`InspectOptions`, report recipe id
0, and refuse a recipe selection with :class:`RecipesUnavailable` ("recipes not available").
"""

from __future__ import annotations

import importlib
from typing import Any

from backend.inspection.service import InspectOptions
from vision.errors import Conflict

__all__ = ["MAX_RECIPE_NUMBER", "RecipesUnavailable", "active_number", "options", "select"]

#: Largest recipe number a PLC can ask for (one unsigned 16-bit register).
MAX_RECIPE_NUMBER = 65535


class RecipesUnavailable(Conflict):
    """This build has no recipes (a recipe selection cannot be honoured)."""


def _service() -> Any | None:
    try:
        return importlib.import_module("backend.recipes.service")
    except ModuleNotFoundError:
        return None


def _number_of(recipe: Any) -> int:
    if recipe is None:
        return 0
    n = recipe.get("number") if isinstance(recipe, dict) else getattr(recipe, "number", 0)
    return int(n or 0)


async def active_number(rt: Any) -> int:
    """Number of the cell's active recipe (0: none, or no recipes in this build)."""
    svc = _service()
    if svc is None:
        return 0
    return _number_of(await svc.active_recipe(rt))


async def select(rt: Any, number: int, *, actor: Any) -> int:
    """Make recipe ``number`` the active one, as ``actor``; returns its number.

    :class:`RecipesUnavailable` without recipes; the recipe service's own errors
    (:class:`~vision.errors.NotFound` for an unknown number) otherwise.
    """
    if (
        isinstance(number, bool)
        or not isinstance(number, int)
        or not 1 <= number <= MAX_RECIPE_NUMBER
    ):
        from vision.errors import InvalidInput

        raise InvalidInput(
            f"recipe number must be an integer in 1..{MAX_RECIPE_NUMBER}, got {number!r}"
        )
    svc = _service()
    if svc is None:
        raise RecipesUnavailable("recipes not available")
    return _number_of(await svc.activate_number(rt, number, actor=actor)) or number


async def options(rt: Any) -> InspectOptions:
    """The options of the next inspection: the active recipe's, else the defaults."""
    svc = _service()
    if svc is None:
        return InspectOptions()
    recipe = await svc.active_recipe(rt)
    if recipe is None:
        return InspectOptions()
    return svc.options_for(recipe, {})
