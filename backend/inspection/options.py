"""How to inspect: :class:`InspectOptions`, checked once where they are made.

The rules of each option live here, once (:func:`check_option`): :class:`InspectOptions`
and a recipe's options (:class:`backend.recipes.model.RecipeOptions`) both apply them, and
the API's request models take their bounds from the constants below.  Inside the
inspection the options are trusted.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Awaitable, Callable
from dataclasses import dataclass, fields
from typing import TYPE_CHECKING, Any

from vision.errors import Conflict, InvalidInput
from vision.recognition import POLICIES

if TYPE_CHECKING:
    from backend.runtime import CellRuntime

__all__ = ["BELT_MODES", "MAX_COUNT", "MAX_RECIPE_MODELS", "MAX_WAIT_S", "InspectOptions",
           "Resolve", "apply_belt_mode", "check_belt_mode", "check_option", "resolved"]  # fmt: skip

log = logging.getLogger(__name__)

#: Longest wait for an object at the station, seconds; most objects in one run.
MAX_WAIT_S = 600.0
MAX_COUNT = 10_000
#: Most models one set of options (a recipe) may name.
MAX_RECIPE_MODELS = 200
#: Belt modes a recipe may set (:data:`robot.sim.world.CONVEYOR_MODES`).
BELT_MODES = ("index", "continuous")


def _number(v: Any) -> bool:
    return not isinstance(v, bool) and isinstance(v, int | float) and math.isfinite(v)


def _names(v: Any) -> bool:
    return (isinstance(v, tuple) and len(v) <= MAX_RECIPE_MODELS
            and all(isinstance(m, str) and 1 <= len(m) <= 64 for m in v))  # fmt: skip


def _pairs(v: Any) -> bool:
    return (isinstance(v, tuple) and len(v) <= MAX_RECIPE_MODELS
            and all(isinstance(p, tuple) and len(p) == 2 and _names(p) for p in v))  # fmt: skip


#: Each option's rule: (whether a value is valid, what a valid value is).
_RULES: dict[str, tuple[Callable[[Any], bool], str]] = {
    "policy": (lambda v: v in POLICIES, f"one of {', '.join(POLICIES)}"),
    "sort": (lambda v: isinstance(v, bool), "true or false"),
    "balance_light": (lambda v: isinstance(v, bool), "true or false"),
    "max_views": (
        lambda v: not isinstance(v, bool) and isinstance(v, int) and 1 <= v <= 3,
        "an integer in 1..3",
    ),
    "wait_s": (lambda v: _number(v) and 0.0 <= v <= MAX_WAIT_S, f"in [0, {MAX_WAIT_S:g}] s"),
    "speed": (lambda v: v is None or (_number(v) and 0.0 < v <= 1.0), "in (0, 1] or null"),
    "threshold": (
        lambda v: v is None or (_number(v) and 0.0 <= v <= 1.0),
        "in [0, 1] or null (automatic)",
    ),
    "belt_mode": (lambda v: v in (None, *BELT_MODES), f"one of {', '.join(BELT_MODES)} or null"),
    "models": (_names, f"a tuple of at most {MAX_RECIPE_MODELS} names"),
    "bins": (_pairs, "(model, bin) name pairs"),
}


def check_option(name: str, value: Any) -> None:
    """:class:`InvalidInput` unless ``value`` is valid for option ``name`` (options without a
    rule, such as a recipe's identity, take any value)."""
    rule = _RULES.get(name)
    if rule is not None and not rule[0](value):
        raise InvalidInput(f"{name} must be {rule[1]}, got {value!r}"[:300])


@dataclass(frozen=True)
class InspectOptions:
    """How to inspect.

    Attributes
    ----------
    policy : {"naive", "top-only", "two-views", "best-next"}
    sort : bool
        Pick and sort into the part's bin (reject bin for unknown / failed); else move to
        the object's approach pose only.
    max_views : int
        1..3.
    wait_s : float
        Longest wait for a part at the station, seconds, of one inspection (a run waits
        until a part comes or it is stopped).
    speed : float, optional
        Arm speed fraction (default: the cell's).
    balance_light : bool
        Scale the views' channels back to the light the models were taught under, by the
        belt's colour round the object (:mod:`vision.recognition.light`); off only to
        measure what it does.
    models : tuple of str
        The models in play (empty: every trained model): an object recognised as another
        model is ``unknown`` (and goes to the reject bin when sorting).
    bins : tuple of (model, bin) pairs
        The bin each named model is sorted into, instead of its part's bin.
    threshold : float, optional
        A fixed global score threshold in [0, 1] (None: the cell's thresholds in force,
        automatic or as set).
    belt_mode : {"index", "continuous"}, optional
        The belt's mode to set before the object comes (None: the belt as it is); needs a
        conveyor the cell can configure (the simulator's).
    recipe_id, recipe_name : optional
        The recipe these options came from (:mod:`backend.recipes`), stored on the row.
    """

    policy: str = "two-views"
    sort: bool = False
    max_views: int = 3
    wait_s: float = 60.0
    speed: float | None = None
    balance_light: bool = True
    models: tuple[str, ...] = ()
    bins: tuple[tuple[str, str], ...] = ()
    threshold: float | None = None
    belt_mode: str | None = None
    recipe_id: int | None = None
    recipe_name: str | None = None

    def __post_init__(self) -> None:
        for f in fields(self):
            check_option(f.name, getattr(self, f.name))

    def bin_of(self, model: str | None) -> str | None:
        """The bin these options send ``model`` to (None: its part's bin)."""
        return next((b for m, b in self.bins if m == model), None) if model else None


#: Where a run reads its options again before each object (the active recipe's, with the
#: request's explicit options over them: :func:`backend.recipes.service.follower`).
Resolve = Callable[[], Awaitable[InspectOptions]]


async def resolved(resolve: Resolve | None, opts: InspectOptions) -> InspectOptions:
    """The options ``resolve`` gives now; ``opts`` (those in force) when there is no
    ``resolve`` or it fails (a database outage, the recipe deleted): the object is
    inspected as the one before, said in the log."""
    if resolve is None:
        return opts
    try:
        return await resolve()
    except Exception:  # the run goes on with the options it has
        log.warning("could not read the recipe again: keeping the options in force", exc_info=True)
        return opts


def check_belt_mode(rt: CellRuntime, opts: InspectOptions) -> None:
    """:class:`Conflict` when the options set a belt mode and the cell's conveyor cannot
    be configured (a fixed station)."""
    if opts.belt_mode is not None and not rt.conveyor.controllable:
        raise Conflict(
            f"{'recipe ' + repr(opts.recipe_name) if opts.recipe_name else 'the options'} sets"
            f" the belt to {opts.belt_mode} mode, and this cell's conveyor cannot be configured"
        )


async def apply_belt_mode(rt: CellRuntime, opts: InspectOptions) -> None:
    """Set the belt to the options' mode (nothing when they set none or it is so already)."""
    check_belt_mode(rt, opts)
    st = rt.conveyor.status()
    if opts.belt_mode is not None and st.mode != opts.belt_mode:
        await rt.conveyor.set_mode(opts.belt_mode, speed_m_s=st.speed_m_s)
