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
"""

from __future__ import annotations

import asyncio
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from types import MappingProxyType
from typing import Any

import numpy as np
from numpy.typing import NDArray
from sqlalchemy import func, select
from sqlalchemy.ext.asyncio import AsyncSession

from backend import audit
from backend.db.models import ObjectModel, RecognitionSettings, TrainedView
from backend.db.session import Database, changed
from backend.heavy import HeavyPool
from backend.recognition.index import LiveIndex
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

#: Global threshold before anything was chosen.
DEFAULT_THRESHOLD = 0.5
#: Target false-accept rate of the automatic (conformal) rule.
DEFAULT_TARGET_FAR = 0.01
#: A pair of models is reported confusable when one passes the other's threshold on at
#: least this share of the other's held-out top views.
CONFUSABLE_RATE = 0.05
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


def _unique(lines: Sequence[str]) -> tuple[str, ...]:
    """``lines`` without repeats, in order."""
    return tuple(dict.fromkeys(lines))
