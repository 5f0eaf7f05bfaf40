"""The PLC links' one seam to recipes (:mod:`backend.recipes.service`): which recipe is
active, selecting one by number, and the inspection options a trigger or a run uses."""

from __future__ import annotations

from typing import Any

from backend.inspection.options import InspectOptions
from backend.recipes import service as svc
from vision.errors import InvalidInput

__all__ = ["MAX_RECIPE_NUMBER", "active_number", "options", "resolver", "select"]

#: Largest recipe number a PLC can send (one unsigned 16-bit register); the recipes
#: themselves are numbered within a smaller range, checked by the recipes' service.
MAX_RECIPE_NUMBER = 65535


async def active_number(rt: Any) -> int:
    """Number of the cell's active recipe (0: none)."""
    recipe = await svc.active_recipe(rt)
    return 0 if recipe is None else int(recipe.number)


async def select(rt: Any, number: int, *, user: Any, link: str) -> int:
    """Make recipe ``number`` the active one, as ``user`` (a :class:`LinkUser`) over
    ``link``; returns its number.

    :class:`~vision.errors.InvalidInput` for a number out of range,
    :class:`~vision.errors.NotFound` for one the cell has not.
    """
    if (
        isinstance(number, bool)
        or not isinstance(number, int)
        or not 1 <= number <= MAX_RECIPE_NUMBER
    ):
        raise InvalidInput(
            f"recipe number must be an integer in 1..{MAX_RECIPE_NUMBER}, got {number!r}"
        )
    recipe = await svc.activate_number(rt, number, actor=user.name, role=user.role.name,
                                       reason=f"selected over {link}")  # fmt: skip
    return int(recipe.number)


async def options(rt: Any) -> InspectOptions:
    """The options of the next inspection: the active recipe's, else the defaults."""
    return await svc.resolve_options(rt, {})


def resolver(rt: Any) -> Any:
    """What a run started by a PLC reads its options from before each object (the active
    recipe then)."""
    return svc.follower(rt, {})
