"""The automatic threshold (chapter section 6) recomputed from the live index after each
teach, stored in ``recognition_settings``, and the thresholds in force for inspections.

:func:`recompute` runs :func:`vision.recognition.choose_threshold` on a copy of the live
index (so inspections are not held up while it runs) and stores the choice (rule, figures,
per-model thresholds, the score distributions and the confusion table) as a new settings row
``chosen_by="auto"``.  An engineer's manual global threshold (``PUT
/api/recognition/settings``) is never overwritten: the automatic choice is then only
reported until the engineer hands the choice back (:func:`back_to_automatic`, ``PUT
/api/recognition/settings`` with ``{"global_threshold": null}``).  A model's own
``threshold`` overrides the automatic per-model one.

An automatic threshold never falls to 0.  :func:`vision.recognition.choose_threshold` keeps
every automatic bar above its own small floor; and when the scores cannot support the
target false-accept rate (the conformal bound is not reached: too few impostor scores), the
choice rests on the largest of a handful of impostor scores, which may all be near 0 (two
models taught once each), so :func:`unsupported_floored` raises it to
:data:`MIN_AUTO_THRESHOLD`, the cell's conservative bar, until the data can carry a
measured one.  With enough impostors (many views, several models, negative images) the
measured threshold stands as chosen.  When the data cannot support the target
false-accept rate, :func:`advice` says in plain words what to add (teach rounds at other
yaws, more models); the teach wizard shows it.

The stored choice (settings rows, the thresholds in force) is in
:mod:`backend.recognition.thresholdstore`, the floor and the advice in
:mod:`backend.recognition.thresholdadvice`; this module re-exports their names.
"""

from __future__ import annotations

import asyncio
from collections.abc import Callable, Sequence

import numpy as np
from numpy.typing import NDArray

from backend import audit
from backend.db.models import RecognitionSettings
from backend.db.session import Database, changed
from backend.heavy import HeavyPool
from backend.recognition.index import LiveIndex
from backend.recognition.thresholdadvice import (
    DEFAULT_TARGET_FAR,
    MIN_AUTO_THRESHOLD,
    RECOMMENDED_ROUNDS,
    _not_chosen_advice,
    advice,
    floored,
    recommended_rounds,
    rounds_recommended,
    teach_rounds,
    unsupported_floored,
)
from backend.recognition.thresholdstore import (
    CONFUSABLE_RATE,
    DEFAULT_THRESHOLD,
    ThresholdOutcome,
    _detail,
    back_to_automatic,
    choice_from_detail,
    confusable_pairs,
    current_choice,
    from_settings,
    latest_settings,
    settings_audit_value,
)
from vision.recognition import ThresholdChoice, ViewIndex, choose_threshold

__all__ = [
    "CONFUSABLE_RATE",
    "DEFAULT_TARGET_FAR",
    "DEFAULT_THRESHOLD",
    "MIN_AUTO_THRESHOLD",
    "RECOMMENDED_ROUNDS",
    "ThresholdOutcome",
    "advice",
    "back_to_automatic",
    "choice_from_detail",
    "confusable_pairs",
    "current_choice",
    "deferred",
    "floored",
    "from_settings",
    "latest_settings",
    "recommended_rounds",
    "recompute",
    "settings_audit_value",
    "teach_rounds",
    "unsupported_floored",
]


def _choose(
    snapshot: bytes,
    target_far: float,
    negatives: Sequence[NDArray[np.uint8]] = (),
    progress: Callable[[int, int], None] | None = None,
) -> tuple[ThresholdChoice, int]:
    index = ViewIndex.from_bytes(snapshot)
    choice = choose_threshold(
        index, negatives=list(negatives), target_far=target_far, progress=progress
    )
    return choice, len(index)


async def deferred(db: Database) -> ThresholdOutcome:
    """What a teach that leaves the choice to a later round reports: the threshold in force
    and the rounds still to teach."""
    async with db.session() as session:
        row = await latest_settings(session)
        rounds = await teach_rounds(session)
        need = await rounds_recommended(session)
    in_force = DEFAULT_THRESHOLD if row is None else row.global_threshold
    tips = tuple(a for a in advice(rounds, recommended=need) if a.startswith("Teach more rounds"))
    return ThresholdOutcome(
        False, None, in_force, "not chosen: deferred to the last round of this teach", (), tips
    )


async def recompute(
    db: Database,
    live: LiveIndex,
    *,
    target_far: float = DEFAULT_TARGET_FAR,
    heavy: HeavyPool | None = None,
    negatives: Sequence[NDArray[np.uint8]] = (),
    signature: str = "",
    progress: Callable[[int, int], None] | None = None,
) -> ThresholdOutcome:
    """Choose the automatic threshold from the live index and store it (module docstring).

    The choice runs in ``heavy``, the runtime's heavy-work pool, taking one of its job
    slots for as long as it waits (a background job: no admission limit); without one, in
    ``asyncio.to_thread``.  ``negatives``: images of no trained object (RGB or grey
    uint8), impostors too (a single model gets a threshold from them).  ``signature`` is
    stored with the choice: what it was chosen from (:mod:`backend.recognition.autothreshold`
    skips a recomputation from the same data).  ``progress(done, total)`` is called from
    the worker thread.
    """
    with live.reading() as index:
        snapshot = index.to_bytes()  # a copy: the choice runs without the lock
    async with db.session() as session:
        rounds = await teach_rounds(session)
        need = await rounds_recommended(session)
    try:
        if heavy is None:
            raw, n_views = await asyncio.to_thread(
                _choose, snapshot, target_far, negatives, progress
            )
        else:
            async with heavy.job(wait_s=None) as work:
                raw, n_views = await work.run(_choose, snapshot, target_far, negatives, progress)
    except ValueError as exc:
        async with db.session() as session:
            row = await latest_settings(session)
        in_force = DEFAULT_THRESHOLD if row is None else row.global_threshold
        tips = _not_chosen_advice(str(exc)) + advice(rounds, recommended=need,
                                                     target_far=target_far)  # fmt: skip
        return ThresholdOutcome(False, None, in_force, f"not chosen: {exc}", (), _unique(tips))
    choice, raised = unsupported_floored(raw)
    tips = _unique(raw.advice + advice(rounds, recommended=need, impostors=len(raw.impostor),
                                       target_far=target_far,
                                       reachable=raw.far_bound is not None))  # fmt: skip
    floor = MIN_AUTO_THRESHOLD if raised else None
    confusable = confusable_pairs(choice)
    async with db.session() as session:
        row = await latest_settings(session)
        if row is not None and row.chosen_by == "manual":
            return ThresholdOutcome(
                False,
                choice.threshold,
                row.global_threshold,
                f"the manual threshold {row.global_threshold:.3f} stays in force; the "
                f"automatic rule would choose {choice.threshold:.3f} ({choice.rule})",
                confusable,
                tips,
                floor,
            )
        detail = _detail(choice, n_views, n_negatives=len(negatives), signature=signature)
        detail.update(advice=list(tips), floor=floor, rounds=rounds)
        changed(session, "recognition_settings")
        session.add(
            RecognitionSettings(
                global_threshold=float(choice.threshold),
                chosen_by="auto",
                detail=detail,
            )
        )
        audit.record(
            session,
            actor=audit.SYSTEM,
            kind="threshold",
            entity_id="global",
            action="auto",
            old=None if row is None else settings_audit_value(row),
            new={
                "global_threshold": float(choice.threshold),
                "chosen_by": "auto",
                "per_model": {k: float(v) for k, v in choice.per_model.items()},
            },
            reason=choice.rule[: audit.MAX_REASON_LENGTH],
        )
    return ThresholdOutcome(True, choice.threshold, choice.threshold, choice.rule, confusable,
                            tips, floor)  # fmt: skip


def _unique(lines: Sequence[str]) -> tuple[str, ...]:
    """``lines`` without repeats, in order."""
    return tuple(dict.fromkeys(lines))
