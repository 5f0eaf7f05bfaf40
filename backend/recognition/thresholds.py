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
"""

from __future__ import annotations

import asyncio
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray
from sqlalchemy import select
from sqlalchemy.ext.asyncio import AsyncSession

from backend import audit
from backend.db.models import ObjectModel, RecognitionSettings
from backend.db.session import Database
from backend.recognition.index import LiveIndex
from vision.recognition import ThresholdChoice, ViewIndex, choose_threshold

__all__ = [
    "CONFUSABLE_RATE",
    "DEFAULT_TARGET_FAR",
    "DEFAULT_THRESHOLD",
    "ThresholdOutcome",
    "back_to_automatic",
    "choice_from_detail",
    "confusable_pairs",
    "current_choice",
    "deferred",
    "latest_settings",
    "recompute",
    "settings_audit_value",
]

#: Global threshold before anything was chosen.
DEFAULT_THRESHOLD = 0.5
#: Target false-accept rate of the automatic (conformal) rule.
DEFAULT_TARGET_FAR = 0.01
#: A pair of models is reported confusable when one passes the other's threshold on at
#: least this share of the other's held-out top views.
CONFUSABLE_RATE = 0.05


@dataclass(frozen=True)
class ThresholdOutcome:
    """What :func:`recompute` did."""

    stored: bool
    """True when a new ``auto`` settings row was written (False: kept the manual one, or
    not enough views to choose)."""
    threshold: float | None
    """The automatic global threshold (None when it could not be chosen)."""
    in_force: float
    """The global threshold inspections use now."""
    reason: str
    """What was done, in words."""
    confusable: tuple[dict[str, Any], ...]
    """Pairs of models alike from the top (viewpoint 1), most confused first."""
    advice: tuple[str, ...] = ()
    """What to add so that the data supports the target false-accept rate, in words."""

    def public(self) -> dict[str, Any]:
        return {
            "stored": self.stored,
            "threshold": self.threshold,
            "in_force": self.in_force,
            "reason": self.reason,
            "confusable_from_top": list(self.confusable),
            "advice": list(self.advice),
        }


async def latest_settings(session: AsyncSession) -> RecognitionSettings | None:
    """The settings row in force (the newest)."""
    return await session.scalar(
        select(RecognitionSettings).order_by(RecognitionSettings.id.desc()).limit(1)
    )


def settings_audit_value(row: RecognitionSettings) -> dict[str, Any]:
    """A settings row as the audit trail stores it (without the score distributions)."""
    out: dict[str, Any] = {"global_threshold": row.global_threshold, "chosen_by": row.chosen_by}
    if row.chosen_by == "auto":
        out["per_model"] = dict(row.detail.get("per_model", {}))
    return out


async def back_to_automatic(session: AsyncSession) -> tuple[RecognitionSettings | None, RecognitionSettings | None]:  # fmt: skip
    """End a manual global threshold: ``(before, after)`` settings rows.

    When the row in force is ``manual``, a new row is added in ``session`` (the caller's
    transaction, with its audit row) that puts the automatic choice back in force: a copy
    of the newest ``auto`` row (its threshold, per-model thresholds and figures, which the
    next teach recomputes from the live index as usual), or the default threshold
    (``chosen_by="default"``) when none was ever chosen.  Otherwise nothing is written and
    ``after`` is ``before`` (already automatic).
    """
    before = await latest_settings(session)
    if before is None or before.chosen_by != "manual":
        return before, before
    auto = await session.scalar(
        select(RecognitionSettings)
        .where(RecognitionSettings.chosen_by == "auto")
        .order_by(RecognitionSettings.id.desc())
        .limit(1)
    )
    if auto is None:
        row = RecognitionSettings(
            global_threshold=DEFAULT_THRESHOLD, chosen_by="default", detail={}
        )
    else:
        row = RecognitionSettings(global_threshold=auto.global_threshold, chosen_by="auto",
                                  detail=dict(auto.detail))  # fmt: skip
    session.add(row)
    await session.flush()
    return before, row


def confusable_pairs(
    choice: ThresholdChoice, *, viewpoint: int = 1, rate: float = CONFUSABLE_RATE
) -> tuple[dict[str, Any], ...]:
    """Pairs ``(a, b)`` where ``b`` passes its threshold on at least ``rate`` of ``a``'s
    held-out views of ``viewpoint``, most confused first."""
    table = choice.confusion.get(viewpoint, {})
    pairs = [
        {"model": a, "confused_with": b, "rate": round(float(r), 4)}
        for a, row in table.items()
        for b, r in row.items()
        if a != b and r >= rate
    ]
    return tuple(sorted(pairs, key=lambda p: (-p["rate"], p["model"], p["confused_with"])))


def _detail(
    choice: ThresholdChoice, n_views: int, *, n_negatives: int = 0, signature: str = ""
) -> dict[str, Any]:
    return {
        "advice": list(choice.advice),
        "negatives": n_negatives,
        "signature": signature,
        "rule": choice.rule,
        "rule_id": choice.rule_id,
        "target_far": choice.target_far,
        "far_bound": choice.far_bound,
        "far": choice.far,
        "frr": choice.frr,
        "per_model": {k: float(v) for k, v in choice.per_model.items()},
        "candidate": float(choice.candidate),
        "per_viewpoint": {str(k): float(v) for k, v in choice.per_viewpoint.items()},
        "per_model_viewpoint": {
            str(vp): {m: float(t) for m, t in row.items()}
            for vp, row in choice.per_model_viewpoint.items()
        },
        "candidate_viewpoint": {str(k): float(v) for k, v in choice.candidate_viewpoint.items()},
        "own_viewpoint": {
            str(vp): {m: float(t) for m, t in row.items()}
            for vp, row in choice.own_viewpoint.items()
        },
        "views": n_views,
        "genuine": [round(float(x), 5) for x in choice.genuine],
        "impostor": [round(float(x), 5) for x in choice.impostor],
        "genuine_models": list(choice.genuine_models),
        "confusion": {
            str(vp): {a: {b: float(r) for b, r in row.items()} for a, row in table.items()}
            for vp, table in choice.confusion.items()
        },
        "confusable_from_top": list(confusable_pairs(choice)),
    }


def choice_from_detail(global_threshold: float, detail: Mapping[str, Any]) -> ThresholdChoice:
    """Rebuild the stored :class:`ThresholdChoice` of an ``auto`` settings row."""
    return ThresholdChoice(
        threshold=float(global_threshold),
        per_model={str(k): float(v) for k, v in detail.get("per_model", {}).items()},
        rule=str(detail.get("rule", "")),
        rule_id=str(detail.get("rule_id", "")),
        target_far=detail.get("target_far"),
        far_bound=detail.get("far_bound"),
        far=float(detail.get("far", math.nan)),
        frr=float(detail.get("frr", math.nan)),
        genuine=np.asarray(detail.get("genuine", []), dtype=np.float64),
        impostor=np.asarray(detail.get("impostor", []), dtype=np.float64),
        genuine_models=tuple(detail.get("genuine_models", [])),
        confusion={
            int(vp): {a: dict(row) for a, row in table.items()}
            for vp, table in detail.get("confusion", {}).items()
        },
        candidate=float(detail.get("candidate", 0.0)),
        per_viewpoint={int(k): float(v) for k, v in detail.get("per_viewpoint", {}).items()},
        per_model_viewpoint={
            int(vp): {str(m): float(t) for m, t in row.items()}
            for vp, row in detail.get("per_model_viewpoint", {}).items()
        },
        candidate_viewpoint={
            int(k): float(v) for k, v in detail.get("candidate_viewpoint", {}).items()
        },
        own_viewpoint={
            int(vp): {str(m): float(t) for m, t in row.items()}
            for vp, row in detail.get("own_viewpoint", {}).items()
        },
        advice=tuple(str(a) for a in detail.get("advice", [])),
    )


async def current_choice(session: AsyncSession) -> ThresholdChoice:
    """The thresholds in force, as :func:`vision.recognition.recognise` takes them: the
    latest settings (automatic per-model thresholds if they were chosen automatically),
    with each model's own threshold overriding its automatic one."""
    row = await latest_settings(session)
    if row is None:
        choice = choice_from_detail(DEFAULT_THRESHOLD, {"rule": "default"})
    elif row.chosen_by == "auto":
        choice = choice_from_detail(row.global_threshold, row.detail)
    else:
        choice = choice_from_detail(row.global_threshold, {"rule": row.chosen_by})
    rows = (
        await session.execute(
            select(ObjectModel.name, ObjectModel.threshold).where(
                ObjectModel.threshold.is_not(None)
            )
        )
    ).all()
    # The query already drops NULL thresholds; the check narrows the type.
    overrides = {name: t for name, t in rows if t is not None}
    if not overrides:
        return choice
    from dataclasses import replace

    per_vp = {vp: {**row, **overrides} for vp, row in choice.per_model_viewpoint.items()}
    for (
        vp
    ) in choice.per_viewpoint:  # the per-viewpoint choice replaces per_model: override there too
        per_vp.setdefault(vp, dict(overrides))
    # A model's own threshold replaces its own bars too (the policies' side-view bars).
    own_vp = {vp: {**row, **overrides} for vp, row in choice.own_viewpoint.items()}
    return replace(
        choice,
        per_model={**choice.per_model, **overrides},
        per_model_viewpoint=per_vp,
        own_viewpoint=own_vp,
    )


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
    """What a teach that leaves the choice to a later round reports: the threshold in force."""
    async with db.session() as session:
        row = await latest_settings(session)
    in_force = DEFAULT_THRESHOLD if row is None else row.global_threshold
    return ThresholdOutcome(
        False, None, in_force, "not chosen: deferred to the last round of this teach", ()
    )


async def recompute(
    db: Database,
    live: LiveIndex,
    *,
    target_far: float = DEFAULT_TARGET_FAR,
    negatives: Sequence[NDArray[np.uint8]] = (),
    signature: str = "",
    progress: Callable[[int, int], None] | None = None,
) -> ThresholdOutcome:
    """Choose the automatic threshold from the live index and store it (module docstring).

    ``negatives``: images of no trained object (RGB or grey uint8), impostors too (a single
    model gets a threshold from them).  ``signature`` is stored with the choice: what it
    was chosen from (:mod:`backend.recognition.autothreshold` skips a recomputation from
    the same data).  ``progress(done, total)`` is called from the worker thread.
    """
    with live.reading() as index:
        snapshot = index.to_bytes()  # a copy: the choice runs without the lock
    try:
        choice, n_views = await asyncio.to_thread(
            _choose, snapshot, target_far, negatives, progress
        )
    except ValueError as exc:
        async with db.session() as session:
            row = await latest_settings(session)
        in_force = DEFAULT_THRESHOLD if row is None else row.global_threshold
        advice = _not_chosen_advice(str(exc))
        return ThresholdOutcome(False, None, in_force, f"not chosen: {exc}", (), advice)
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
                choice.advice,
            )
        session.add(
            RecognitionSettings(
                global_threshold=float(choice.threshold),
                chosen_by="auto",
                detail=_detail(choice, n_views, n_negatives=len(negatives), signature=signature),
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
    return ThresholdOutcome(
        True, choice.threshold, choice.threshold, choice.rule, confusable, choice.advice
    )


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
