"""What a recipe is: a named, numbered inspection configuration of one cell (pure).

A :class:`Recipe` holds the options a run takes from it (:class:`RecipeOptions`: policy,
views at most, sorting, a fixed threshold or the cell's automatic ones, the belt's mode,
the arm's speed, light balance), the models in play and the bin of each.
:func:`options_for` turns one, with the explicit options of a request over it, into the
:class:`~backend.inspection.options.InspectOptions` an inspection or a run takes.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, fields, replace
from datetime import datetime
from typing import Any

from backend.inspection.options import MAX_RECIPE_MODELS, InspectOptions, check_option
from backend.recognition.models import NAME_PATTERN
from vision.errors import InvalidInput

__all__ = ["MAX_NUMBER", "MAX_RECIPES", "OPTION_KEYS", "Recipe", "RecipeOptions",
           "check_bins", "check_models", "check_name", "check_number", "options_for"]  # fmt: skip

#: Recipe numbers run 1..MAX_NUMBER (what a PLC selects one by).
MAX_NUMBER = 9999
#: Most recipes one cell may hold.
MAX_RECIPES = 1000
#: Longest description, characters.
MAX_DESCRIPTION = 2000


@dataclass(frozen=True)
class RecipeOptions:
    """The inspection options a recipe fixes (see :class:`InspectOptions` for each)."""

    #: Recognition policy: ``naive``, ``top-only``, ``two-views`` or ``best-next``.
    policy: str = "two-views"
    #: Views taken at most, 1..3.
    max_views: int = 3
    #: Pick and sort into the bins (else the approach pose only).
    sort: bool = False
    #: Fixed global score threshold in [0, 1]; None: the cell's thresholds (automatic or set).
    threshold: float | None = None
    #: ``index`` or ``continuous``; None: the belt as it is.
    belt_mode: str | None = None
    #: Arm speed fraction in (0, 1]; None: the cell's.
    speed: float | None = None
    #: Scale the views back to the teach light by the belt's colour.
    balance_light: bool = True

    def __post_init__(self) -> None:
        for f in fields(self):  # the inspection options' own rules
            check_option(f.name, getattr(self, f.name))

    def as_dict(self) -> dict[str, Any]:
        """The stored (JSON) form."""
        return {f.name: getattr(self, f.name) for f in fields(self)}

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> RecipeOptions:
        """From the stored form; keys it does not know are ignored (a newer row), values
        checked."""
        known = {f.name for f in fields(cls)}
        return cls(**{k: v for k, v in data.items() if k in known})


#: The option names a recipe holds (a request's explicit options may override them).
OPTION_KEYS = tuple(f.name for f in fields(RecipeOptions))


@dataclass(frozen=True)
class Recipe:
    """One recipe of a cell, as stored."""

    #: Database id.
    id: int
    #: Unique per cell (a word: letters, digits, ``-``, ``_``, ``.``).
    name: str
    #: 1..9999, unique per cell: what a PLC selects the recipe by.
    number: int
    #: What the options fix.
    options: RecipeOptions
    #: Models in play, by name (empty: every trained model).
    models: tuple[str, ...]
    #: (model, bin) pairs: the bin each named model is sorted into.
    bins: tuple[tuple[str, str], ...]
    #: Free text for the engineer.
    description: str
    #: Whether it is the cell's active recipe.
    active: bool
    created_at: datetime
    updated_at: datetime

    # The options' fields read as the recipe's own (``recipe.policy``).
    @property
    def policy(self) -> str:
        return self.options.policy

    @property
    def max_views(self) -> int:
        return self.options.max_views

    @property
    def sort(self) -> bool:
        return self.options.sort

    @property
    def threshold(self) -> float | None:
        return self.options.threshold

    @property
    def belt_mode(self) -> str | None:
        return self.options.belt_mode

    @property
    def speed(self) -> float | None:
        return self.options.speed

    @property
    def balance_light(self) -> bool:
        return self.options.balance_light

    def public(self) -> dict[str, Any]:
        """The API's form."""
        return {
            "id": self.id,
            "name": self.name,
            "number": self.number,
            "description": self.description,
            **self.options.as_dict(),
            "models": list(self.models),
            "bins": dict(self.bins),
            "active": self.active,
            "created_at": self.created_at.isoformat(),
            "updated_at": self.updated_at.isoformat(),
        }


def check_name(name: object) -> str:
    """A recipe name (as model names: a word of 1..64 characters)."""
    if not isinstance(name, str) or not NAME_PATTERN.match(name):
        raise InvalidInput(
            f"name must be 1..64 letters, digits, '-', '_' or '.', starting with a letter or "
            f"digit, got {name!r}"[:300]
        )
    return name


def check_number(number: object) -> int:
    """A recipe number, 1..:data:`MAX_NUMBER`."""
    if isinstance(number, bool) or not isinstance(number, int) or not 1 <= number <= MAX_NUMBER:
        raise InvalidInput(f"number must be an integer in 1..{MAX_NUMBER}, got {number!r}"[:300])
    return number


def check_models(models: object) -> tuple[str, ...]:
    """Model names, distinct, at most :data:`MAX_RECIPE_MODELS` (their existence is the
    service's to check)."""
    if not isinstance(models, list | tuple) or len(models) > MAX_RECIPE_MODELS:
        raise InvalidInput(f"models must be a list of at most {MAX_RECIPE_MODELS} model names")
    out = tuple(check_name(m) for m in models)
    if len(set(out)) != len(out):
        raise InvalidInput(f"models must be distinct, got {list(out)!r}"[:300])
    return out


def check_bins(bins: object, models: tuple[str, ...]) -> tuple[tuple[str, str], ...]:
    """``{model: bin}`` as sorted pairs; with ``models`` given, each model one of them."""
    if not isinstance(bins, Mapping) or len(bins) > MAX_RECIPE_MODELS:
        raise InvalidInput(f"bins must be an object of at most {MAX_RECIPE_MODELS} model: bin")
    out = tuple(sorted((check_name(m), check_name(b)) for m, b in bins.items()))
    if models:
        stray = [m for m, _ in out if m not in models]
        if stray:
            raise InvalidInput(f"bins name models not in the recipe's models: {stray!r}"[:300])
    return out


def options_for(recipe: Recipe | None, overrides: Mapping[str, Any]) -> InspectOptions:
    """The options of an inspection or a run: the defaults, then ``recipe``'s (None: no
    recipe), then the request's explicit ``overrides`` (any :class:`InspectOptions` field
    but the recipe's identity); the result names the recipe it came from."""
    allowed = {f.name for f in fields(InspectOptions)} - {"recipe_id", "recipe_name"}
    bad = sorted(set(overrides) - allowed)
    if bad:
        raise InvalidInput(f"unknown options {bad!r}; options are {sorted(allowed)!r}"[:400])
    if recipe is None:
        return InspectOptions(**overrides)
    base = InspectOptions(
        **recipe.options.as_dict(), models=recipe.models, bins=recipe.bins,
        recipe_id=recipe.id, recipe_name=recipe.name,
    )  # fmt: skip
    return replace(base, **overrides) if overrides else base
