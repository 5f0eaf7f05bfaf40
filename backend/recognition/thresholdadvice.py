"""The floor of an automatic threshold and the advice on what to teach: the teach rounds a
model of each kind needs, the rounds taught, and what to add when the data cannot support
the target false-accept rate (see :mod:`backend.recognition.thresholds`)."""

from __future__ import annotations

import math
from collections.abc import Mapping
from types import MappingProxyType
from typing import Any

from sqlalchemy import func, select
from sqlalchemy.ext.asyncio import AsyncSession

from backend.db.models import ObjectModel, TrainedView
from vision.recognition import ThresholdChoice

#: Target false-accept rate of the automatic (conformal) rule.
DEFAULT_TARGET_FAR = 0.01

#: Lowest automatic threshold.  The automatic rule with enough data chose 0.155 (twelve
#: models taught at four yaws) to 0.241 (eight yaws) in the simulated cell's campaigns, and
#: an untrained part turned off a taught yaw scored up to 0.10-0.15 from the top: a bar
#: below this lets untrained parts through as models.
MIN_AUTO_THRESHOLD = 0.15
#: Teach rounds (object yaws spread evenly over the whole turn) a model of each kind needs
#: to be recognised at any yaw; the wizard and ``visioncell models teach`` guide to them.
#: A 3d model is decided by its side views, which the 5-DOF arm can only take from two
#: azimuths: a side view verifies an object turned some 20 deg off a taught yaw poorly,
#: so the object itself must be shown at many yaws (the end-to-end campaigns named every
#: trained object at random yaw with eight rounds, 111 of 120 plain parts with four).  A
#: 2d model (a wheel) is decided from the top view, whose features are rotation
#: invariant and which the teach already takes at three camera rolls: one round names it
#: at any yaw.
RECOMMENDED_ROUNDS: Mapping[str, int] = MappingProxyType({"2d": 1, "3d": 8})


def recommended_rounds(kind: str) -> int:
    """Teach rounds a model of ``kind`` (``"2d"`` or ``"3d"``) needs to be recognised at
    any yaw (:data:`RECOMMENDED_ROUNDS`); raises ``ValueError`` for another kind."""
    if kind not in RECOMMENDED_ROUNDS:
        raise ValueError(f"kind must be '2d' or '3d', got {kind!r}")
    return RECOMMENDED_ROUNDS[kind]


def unsupported_floored(choice: ThresholdChoice) -> tuple[ThresholdChoice, bool]:
    """:func:`floored` to :data:`MIN_AUTO_THRESHOLD` when the choice could not bound its
    false-accept rate (no conformal bound: too few impostor scores), else ``choice`` as
    measured; and whether any bar was raised."""
    if choice.far_bound is not None:
        return choice, False
    return floored(choice)


def floored(
    choice: ThresholdChoice, floor: float = MIN_AUTO_THRESHOLD
) -> tuple[ThresholdChoice, bool]:
    """``choice`` with every threshold it holds (global, per model, per viewpoint, the
    candidates and the own bars) raised to at least ``floor``; and whether any was raised
    (the rule's text then says so)."""
    from dataclasses import replace

    if not (math.isfinite(floor) and 0.0 <= floor <= 1.0):
        raise ValueError(f"floor must be in [0, 1], got {floor!r}")

    def up(v: float) -> float:
        return max(float(v), floor)

    def up_map(d: Mapping[Any, float]) -> dict[Any, float]:
        return {k: up(v) for k, v in d.items()}

    raised = (
        choice.threshold < floor
        or any(v < floor for v in choice.per_model.values())
        or any(v < floor for v in choice.per_viewpoint.values())
        or any(v < floor for row in choice.per_model_viewpoint.values() for v in row.values())
    )
    if not raised and choice.candidate >= floor:
        return choice, False
    rule = choice.rule
    if choice.threshold < floor:
        rule += f"; raised from {choice.threshold:.3f} to the floor {floor:.3f}"
    elif raised:
        rule += f"; per-model or per-viewpoint thresholds raised to the floor {floor:.3f}"
    out = replace(
        choice,
        threshold=up(choice.threshold),
        per_model=up_map(choice.per_model),
        rule=rule,
        candidate=up(choice.candidate),
        per_viewpoint=up_map(choice.per_viewpoint),
        per_model_viewpoint={vp: up_map(r) for vp, r in choice.per_model_viewpoint.items()},
        candidate_viewpoint=up_map(choice.candidate_viewpoint),
        own_viewpoint={vp: up_map(r) for vp, r in choice.own_viewpoint.items()},
    )
    return out, raised or choice.candidate < floor


def advice(
    rounds: Mapping[str, int],
    *,
    recommended: Mapping[str, int] | None = None,
    impostors: int | None = None,
    target_far: float = DEFAULT_TARGET_FAR,
    reachable: bool = True,
) -> tuple[str, ...]:
    """What to add so the automatic threshold can be trusted, in plain words.

    Parameters
    ----------
    rounds : mapping of model name to int
        Teach rounds of each model (distinct object yaws of its top views).
    recommended : mapping of model name to int, optional
        Rounds each model needs (:func:`recommended_rounds` of its kind); a model not
        listed needs a 3d model's.
    impostors : int, optional
        Impostor scores the rule had (one per trained view, scored against the other models).
    target_far : float
        The target false-accept rate.
    reachable : bool
        Whether the rule reached the target with the scores it had.
    """
    out: list[str] = []
    if len(rounds) < 2:
        out.append(
            "Teach at least one more model: the automatic threshold is chosen from how the "
            "models score each other's views, so it needs two or more."
        )
    need = dict(recommended or {})
    default = RECOMMENDED_ROUNDS["3d"]
    short = sorted((n, r, need.get(n, default)) for n, r in rounds.items()
                   if r < need.get(n, default))  # fmt: skip
    if short:
        listed = ", ".join(f"{n} ({r} of {k})" for n, r, k in short)
        three = RECOMMENDED_ROUNDS["3d"]
        out.append(
            f"Teach more rounds: a 3d model is recognised at any yaw after {three} rounds, "
            f"the object turned {360 // three} degrees between them (a 2d model after "
            f"{RECOMMENDED_ROUNDS['2d']}); short of that: {listed}."
        )
    if not reachable and impostors is not None:
        n_imp = math.ceil(1.0 / target_far - 1.0)
        out.append(
            f"A false-accept rate of {target_far * 100:g} % needs {n_imp} views scored against "
            f"other models; the trained views give {impostors}. More rounds or more models "
            f"add them; until then the threshold is the largest score another model's view "
            f"reached, and at least {MIN_AUTO_THRESHOLD:.2f}."
        )
    return tuple(out)


async def teach_rounds(session: AsyncSession) -> dict[str, int]:
    """Teach rounds of every model with trained views: the distinct object yaws of its top
    views (a round turns the object; its camera rolls share the yaw)."""
    rows = await session.execute(
        select(ObjectModel.name, func.count(func.distinct(TrainedView.yaw_rad)))
        .join(TrainedView, TrainedView.model_id == ObjectModel.id)
        .where(TrainedView.viewpoint == 1)
        .group_by(ObjectModel.name)
    )
    return {str(n): int(c) for n, c in rows}


async def rounds_recommended(session: AsyncSession) -> dict[str, int]:
    """Teach rounds every model needs, by its kind (:func:`recommended_rounds`)."""
    rows = await session.execute(select(ObjectModel.name, ObjectModel.kind))
    return {str(n): recommended_rounds(k.value) for n, k in rows}


def _not_chosen_advice(reason: str) -> tuple[str, ...]:
    """What to add when no threshold could be chosen at all, in plain words."""
    if "at least two models" in reason:
        return (
            "Add a second model, or negative images (the empty belt, other things in the "
            "scene): with one model and nothing else there is no impostor to measure the "
            "false accepts against.",
        )
    if "two trained views" in reason:
        return ("Add at least two views of a model at the same viewpoint.",)
    return ()
