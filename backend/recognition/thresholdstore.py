"""The threshold choice as ``recognition_settings`` rows store it: the row in force, the
choice rebuilt from a row's detail (the thresholds inspections use), an outcome told from
a stored row, and the hand-back from a manual threshold to the automatic one."""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
from sqlalchemy import select
from sqlalchemy.ext.asyncio import AsyncSession

from backend.db.models import ObjectModel, RecognitionSettings
from backend.db.session import changed
from backend.recognition.thresholdadvice import unsupported_floored
from vision.recognition import ThresholdChoice

#: Global threshold before anything was chosen.
DEFAULT_THRESHOLD = 0.5

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
    """What to add (teach rounds, models) when the data cannot support the target rate."""
    floor: float | None = None
    """The floor the automatic threshold was raised to, None when the rule's own was kept."""
    skipped: bool = False
    """True when the choice in force had been made from the same data (nothing chosen)."""
    negatives: int | None = None
    """Negative images the choice scored as impostors (None when not told)."""

    def public(self) -> dict[str, Any]:
        return {
            "stored": self.stored,
            "threshold": self.threshold,
            "in_force": self.in_force,
            "reason": self.reason,
            "confusable_from_top": list(self.confusable),
            "advice": list(self.advice),
            "floor": self.floor,
            "skipped": self.skipped,
            "negatives": self.negatives,
        }


def from_settings(row: RecognitionSettings, why: str) -> ThresholdOutcome:
    """The outcome of a choice already in force (``row``, chosen automatically from the same
    data), told as ``why``: its threshold, rule, advice and confusable pairs as stored."""
    detail = row.detail or {}
    floor = detail.get("floor")
    return ThresholdOutcome(
        False,
        float(row.global_threshold),
        float(row.global_threshold),
        f"{why}: {detail.get('rule', '')}".rstrip(": "),
        tuple(detail.get("confusable_from_top", ())),
        tuple(str(a) for a in detail.get("advice", ())),
        None if floor is None else float(floor),
        skipped=True,
        negatives=detail.get("negatives"),
    )


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
    changed(session, "recognition_settings")
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
        # Floored again: a row stored before the floor existed may hold 0.
        choice = unsupported_floored(choice_from_detail(row.global_threshold, row.detail))[0]
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
