"""Trained views in the database: add (teach, upload, import), delete, re-extract stale
features.  Every change is made in one transaction and mirrored in the live index only once
it is certain (a failed commit takes its views back out), so the database and the index
never disagree and bad input leaves no row behind.  Reading them (list, images) is in
:mod:`backend.recognition.viewreads`, re-exported here.
"""

from __future__ import annotations

import asyncio
import math
from collections.abc import Awaitable, Callable, Sequence
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray
from sqlalchemy import delete, select

from backend import audit
from backend.db.models import ObjectModel, TrainedView
from backend.db.session import Database, changed
from backend.recognition import images as im
from backend.recognition.index import IndexedModel, LiveIndex
from backend.recognition.models import get_model
from backend.recognition.viewreads import _view_total, get_view, list_views, view_image, view_public
from vision.errors import Conflict, InvalidInput
from vision.features import Features

__all__ = [
    "MAX_VIEWS_PER_MODEL",
    "MAX_VIEWS_PER_REQUEST",
    "MIN_FEATURES",
    "TooFewFeatures",
    "ViewInput",
    "add_views",
    "delete_view",
    "get_view",
    "list_views",
    "reextract_views",
    "view_image",
    "view_public",
]

#: Most trained views of one model (3 viewpoints x yaw steps x retakes, with room).
MAX_VIEWS_PER_MODEL = 500
#: Most views one upload or teach adds.
MAX_VIEWS_PER_REQUEST = 72
#: Fewest features a view needs (a match is verified by an affine fit: 3 points).
MIN_FEATURES = 3
Source = Literal["teach", "upload", "import"]


@dataclass(frozen=True, eq=False)
class ViewInput:
    """One view to store.

    Attributes
    ----------
    image : ndarray of shape (H, W, 3), uint8
        RGB image.
    viewpoint : int
        1 (top), 2 or 3 (sides).
    mask : ndarray of shape (H, W), bool, optional
        The object's region; features are extracted inside it.
    yaw_rad, roll_rad : float
        Object yaw relative to the taught pose, and camera roll (q5), radians.
    source : str
        ``teach``, ``upload`` or ``import``.
    joints : ndarray of shape (5,), optional
        Arm joints at exposure (radians).
    T_base_cam : ndarray of shape (4, 4), optional
        Camera pose at exposure (metres).
    name : str
        What to call the view in error messages (a file name).
    """

    image: NDArray[np.uint8]
    viewpoint: int
    mask: NDArray[np.bool_] | None = None
    yaw_rad: float = 0.0
    roll_rad: float = 0.0
    source: Source = "upload"
    joints: NDArray[np.float64] | None = None
    T_base_cam: NDArray[np.float64] | None = None
    name: str = "view"

    def __post_init__(self) -> None:
        img = self.image
        if not isinstance(img, np.ndarray) or img.dtype != np.uint8 or img.ndim != 3:
            raise InvalidInput(f"{self.name}: the image must be RGB uint8 (H, W, 3)")
        if isinstance(self.viewpoint, bool) or self.viewpoint not in (1, 2, 3):
            raise InvalidInput(f"{self.name}: viewpoint must be 1, 2 or 3, got {self.viewpoint!r}")
        for what in ("yaw_rad", "roll_rad"):
            v = getattr(self, what)
            if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v):
                raise InvalidInput(f"{self.name}: {what} must be a finite number, got {v!r}")
            if abs(v) > 2 * math.pi:
                raise InvalidInput(f"{self.name}: {what} must be within +-2 pi rad, got {v!r}")
        if self.mask is not None:
            m = self.mask
            if m.shape != img.shape[:2] or m.dtype != np.bool_:
                raise InvalidInput(f"{self.name}: the mask must be boolean of the image's size")
            if not m.any():
                raise InvalidInput(f"{self.name}: the mask is empty")
        if self.source not in ("teach", "upload", "import"):
            raise InvalidInput(f"source must be teach, upload or import, got {self.source!r}")


def _audit_value(row: TrainedView, model_name: str) -> dict[str, Any]:
    """The fields of a view as the audit trail stores them (no image data)."""
    return {
        "model_id": row.model_id,
        "model": model_name,
        "viewpoint": row.viewpoint,
        "source": row.source,
        "width": row.width,
        "height": row.height,
        "keypoints": row.keypoint_count,
        "descriptor": {"kind": row.descriptor_kind, "version": row.descriptor_version},
        "yaw_rad": row.yaw_rad,
        "roll_rad": row.roll_rad,
    }


class TooFewFeatures(InvalidInput):
    """A view with fewer than :data:`MIN_FEATURES` features inside the object's region."""


def _prepare_one(live: LiveIndex, v: ViewInput) -> tuple[Features, bytes, bytes | None, bytes]:
    """Extract the features of one view and encode its images (CPU work, in a thread)."""
    feats = live.extract(v.image, v.mask)
    if len(feats) < MIN_FEATURES:
        raise TooFewFeatures(
            f"{v.name}: only {len(feats)} {live.method} features inside the object's "
            f"region (need {MIN_FEATURES}); use a sharper, larger or more textured view"
        )
    return (
        feats,
        im.encode_png(v.image),
        None if v.mask is None else im.encode_mask_png(v.mask),
        im.thumbnail(v.image, v.mask),
    )


def _prepare(
    live: LiveIndex, views: Sequence[ViewInput], skip_weak: bool = False
) -> list[tuple[Features, bytes, bytes | None, bytes] | TooFewFeatures]:
    """:func:`_prepare_one` of every view (CPU work, run in a thread); with ``skip_weak``
    a view with too few features gives its error in its place instead of raising it."""
    return [_prepare_or_weak(live, v, skip_weak) for v in views]


def _prepare_or_weak(
    live: LiveIndex, v: ViewInput, skip_weak: bool
) -> tuple[Features, bytes, bytes | None, bytes] | TooFewFeatures:
    try:
        return _prepare_one(live, v)
    except TooFewFeatures as exc:
        if not skip_weak:
            raise
        return exc


async def add_views(
    db: Database,
    live: LiveIndex,
    model_id: int,
    views: Sequence[ViewInput],
    *,
    replace: bool = False,
    by: audit.By | None = None,
    run: Callable[..., Awaitable[Any]] | None = None,
    skipped: list[tuple[int, str]] | None = None,
    needs_viewpoint: int | None = None,
) -> list[TrainedView]:
    """Store ``views`` of a model (all or none) and add them to the live index; with
    ``replace``, the model's earlier views are deleted in the same transaction.

    ``skipped`` (a list): a view with too few features (:class:`TooFewFeatures`) is left
    out instead of refusing them all, and ``(index, reason)`` is appended for it; the
    error is raised when every view is such, or when every view of ``needs_viewpoint``
    given is such (a teach's top views: without one the part cannot be matched).  The
    rows are those of the views kept, in order.

    ``run`` runs the feature extraction of each view (a request's heavy-work job,
    :meth:`backend.heavy.HeavyJob.run`: one view per unit, so a client that leaves stops
    it between views); None: all views in one ``asyncio.to_thread`` call."""
    if not views:
        raise InvalidInput("no views given")
    if len(views) > MAX_VIEWS_PER_REQUEST:
        raise InvalidInput(f"at most {MAX_VIEWS_PER_REQUEST} views at once, got {len(views)}")
    async with db.session() as session:
        model = IndexedModel.of(await get_model(session, model_id))
        have = 0 if replace else await _view_total(session, model_id)
    if have + len(views) > MAX_VIEWS_PER_MODEL:
        raise Conflict(
            f"model {model.name!r} has {have} views; {len(views)} more would pass the limit "
            f"of {MAX_VIEWS_PER_MODEL}: delete some first"
        )
    skip_weak = skipped is not None
    if run is None:
        ready = await asyncio.to_thread(_prepare, live, views, skip_weak)
    else:
        ready = [await run(_prepare_or_weak, live, v, skip_weak) for v in views]
    weak = [(k, r) for k, r in enumerate(ready) if isinstance(r, TooFewFeatures)]
    if weak and len(weak) == len(ready):
        raise weak[0][1]
    needed = [k for k, v in enumerate(views) if v.viewpoint == needs_viewpoint]
    needed_weak = [r for k, r in weak if k in needed]
    if needed and len(needed_weak) == len(needed):
        raise needed_weak[0]
    if skipped is not None:
        skipped.extend((k, exc.detail) for k, exc in weak)
    views = [v for v, r in zip(views, ready, strict=True) if not isinstance(r, TooFewFeatures)]
    prepared = [r for r in ready if not isinstance(r, TooFewFeatures)]
    added: list[int] = []
    try:
        async with db.session() as session:
            row_model = await get_model(session, model_id)  # still there, and locked in
            by = by or audit.By()
            old: list[int] = []
            if replace:
                old = list(
                    await session.scalars(
                        select(TrainedView.id).where(TrainedView.model_id == model_id)
                    )
                )
                for vid in old:
                    audit.record(
                        session,
                        actor=by.actor,
                        kind="view",
                        entity_id=vid,
                        action="delete",
                        old={"model_id": model_id, "model": row_model.name, "replaced": True},
                        new=None,
                        reason=by.reason,
                    )
                await session.execute(delete(TrainedView).where(TrainedView.model_id == model_id))
            rows = []
            for v, (feats, png, mask_png, thumb) in zip(views, prepared, strict=True):
                row = TrainedView(
                    model_id=row_model.id,
                    viewpoint=v.viewpoint,
                    image_png=png,
                    mask_png=mask_png,
                    thumbnail_jpeg=thumb,
                    width=int(v.image.shape[1]),
                    height=int(v.image.shape[0]),
                    features=feats.to_bytes(),
                    descriptor_kind=feats.method,
                    descriptor_version=live.version,
                    keypoint_count=len(feats),
                    yaw_rad=float(v.yaw_rad),
                    roll_rad=float(v.roll_rad),
                    source=v.source,
                    joints=None if v.joints is None else [float(x) for x in v.joints],
                    T_base_cam=None if v.T_base_cam is None else np.asarray(v.T_base_cam).tolist(),
                )
                session.add(row)
                rows.append(row)
            await session.flush()
            changed(session, "trained_views")
            for row in rows:
                audit.record(
                    session,
                    actor=by.actor,
                    kind="view",
                    entity_id=row.id,
                    action="add",
                    old=None,
                    new=_audit_value(row, row_model.name),
                    reason=by.reason,
                )
            for row, v, (feats, *_rest) in zip(rows, views, prepared, strict=True):
                live.add_view(model, row.id, row.viewpoint, feats, image=v.image, mask=v.mask)
                added.append(row.id)
    except BaseException:
        for vid in added:
            live.remove_view(vid)
        raise
    for vid in old:
        live.remove_view(vid)
    return rows


async def delete_view(
    db: Database, live: LiveIndex, model_id: int, view_id: int, *, by: audit.By | None = None
) -> None:
    """Delete one view from the database and the live index."""
    by = by or audit.By()
    async with db.session() as session:
        row = await get_view(session, model_id, view_id)
        model = await get_model(session, model_id)
        audit.record(
            session,
            actor=by.actor,
            kind="view",
            entity_id=row.id,
            action="delete",
            old=_audit_value(row, model.name),
            new=None,
            reason=by.reason,
        )
        await session.delete(row)
        changed(session, "trained_views")
    live.remove_view(view_id)


async def reextract_views(
    db: Database,
    live: LiveIndex,
    *,
    model_id: int | None = None,
    only_stale: bool = True,
    by: audit.By | None = None,
) -> int:
    """Extract features again from the stored images (and masks) of stale views (or of
    every view with ``only_stale=False``), store them and index them; return the count."""
    by = by or audit.By()
    async with db.session() as session:
        q = select(TrainedView.id).order_by(TrainedView.id)
        if model_id is not None:
            await get_model(session, model_id)
            q = q.where(TrainedView.model_id == model_id)
        ids = list(await session.scalars(q))
    if only_stale:
        ids = [i for i in ids if i in live.stale]
    done = 0
    for vid in ids:
        async with db.session() as session:
            row = await session.get(TrainedView, vid)
            if row is None:
                continue
            model = IndexedModel.of(await session.get_one(ObjectModel, row.model_id))
            rgb = im.rgb_from_png(row.image_png)
            mask = None if row.mask_png is None else im.mask_from_png(row.mask_png)
            feats = await asyncio.to_thread(live.extract, rgb, mask)
            if len(feats) < MIN_FEATURES:
                raise InvalidInput(f"view {vid}: only {len(feats)} features on re-extraction")
            before = _audit_value(row, model.name)
            row.features = feats.to_bytes()
            row.descriptor_kind = feats.method
            row.descriptor_version = live.version
            row.keypoint_count = len(feats)
            await session.flush()
            changed(session, "trained_views")
            audit.record(
                session,
                actor=by.actor,
                kind="view",
                entity_id=vid,
                action="reextract",
                old=before,
                new=_audit_value(row, model.name),
                reason=by.reason,
            )
            live.remove_view(vid)
            live.add_view(model, vid, row.viewpoint, feats, image=rgb, mask=mask)
        done += 1
    return done
