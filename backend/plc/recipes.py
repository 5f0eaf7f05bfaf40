"""The PLC links' one seam to recipes: which recipe is active, selecting one by number, and
the inspection options a trigger or a run uses.

Recipes live in ``backend.recipes.service`` (``active_recipe(rt)``, ``activate_number(rt,
number, *, actor, role, reason)``, ``resolve_options(rt, overrides)``, ``follower(rt,
overrides)``).  A build without that module still triggers and runs, with the default
:class:`InspectOptions`, reports recipe 0, and refuses a selection with
:class:`RecipesUnavailable` ("recipes not available").
"""

from __future__ import annotations

import importlib
from typing import Any

from backend.inspection.service import InspectOptions
from vision.errors import Conflict, InvalidInput

__all__ = ["MAX_RECIPE_NUMBER", "RecipesUnavailable", "active_number", "options", "resolver",
           "select"]  # fmt: skip

#: Largest recipe number a PLC can send (one unsigned 16-bit register).
MAX_RECIPE_NUMBER = 65535


class RecipesUnavailable(Conflict):
    """This build has no recipes (a recipe selection cannot be honoured)."""


def _service() -> Any | None:
    try:
        return importlib.import_module("backend.recipes.service")
    except ModuleNotFoundError:
        return None


async def active_number(rt: Any) -> int:
    """Number of the cell's active recipe (0: none, or no recipes in this build)."""
    svc = _service()
    if svc is None:
        return 0
    recipe = await svc.active_recipe(rt)
    return 0 if recipe is None else int(recipe.number)


async def select(rt: Any, number: int, *, user: Any, link: str) -> int:
    """Make recipe ``number`` the active one, as ``user`` (a :class:`LinkUser`) over
    ``link``; returns its number.

    :class:`RecipesUnavailable` without recipes; :class:`~vision.errors.InvalidInput` for a
    number out of range, :class:`~vision.errors.NotFound` for one the cell has not.
    """
    if (
        isinstance(number, bool)
        or not isinstance(number, int)
        or not 1 <= number <= MAX_RECIPE_NUMBER
    ):
        raise InvalidInput(
            f"recipe number must be an integer in 1..{MAX_RECIPE_NUMBER}, got {number!r}"
        )
    svc = _service()
    if svc is None:
        raise RecipesUnavailable("recipes not available")
    recipe = await svc.activate_number(rt, number, actor=user.name, role=user.role.name,
                                       reason=f"selected over {link}")  # fmt: skip
    return int(recipe.number)


async def options(rt: Any) -> InspectOptions:
    """The options of the next inspection: the active recipe's, else the defaults."""
    svc = _service()
    if svc is None:
        return InspectOptions()
    return await svc.resolve_options(rt, {})


def resolver(rt: Any) -> Any | None:
    """What a run started by a PLC reads its options from before each object (the active
    recipe then), or None without recipes."""
    svc = _service()
    return None if svc is None else svc.follower(rt, {})
