"""The live index: every trained view of the database in one :class:`vision.recognition.ViewIndex`.

It is built once from the database at start-up (from the stored features: nothing is
re-extracted) and then updated in place on every change (a view taught, uploaded or
deleted, a model renamed or deleted), so an inspection never rebuilds it.  Views whose
stored features were extracted by another descriptor version than the one this VisionCell
extracts are refused (listed in :attr:`LiveIndex.stale`, with the way to re-extract them
from their stored images) rather than mixed with the others.

The index is not thread-safe and recognition runs in worker threads, so readers and writers
share one lock: ``with live.reading() as index: recognise(index, ...)``.

Changes made by another process of the plant (another cell on the same PostgreSQL database,
or the CLI) reach the index through :meth:`LiveIndex.diff` and :meth:`LiveIndex.apply`,
driven by :class:`backend.recognition.sync.IndexSync`; every change method is idempotent so
that a change seen both locally and from the database is applied once.

:class:`LiveIndex` takes stored features in (checking their descriptor version): loading,
syncing, adding a view.  Its in-memory side (state, reading, listeners, the changes that
take no features in) is :class:`backend.recognition.indexcore.IndexCore`, and the values it
keeps and tells are in :mod:`backend.recognition.indextypes`; this module re-exports them.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Mapping
from typing import Any

import numpy as np
from numpy.typing import NDArray
from sqlalchemy import select

from backend.db.models import ObjectModel, TrainedView
from backend.db.session import Database
from backend.recognition.indexcore import FEATURE_OPTIONS, IndexCore, colour_of
from backend.recognition.indextypes import (
    VIEW_ROW_COLUMNS,
    IndexDiff,
    IndexedModel,
    LoadReport,
    StaleView,
    ViewRow,
)
from vision.errors import InvalidInput, VisionCellError
from vision.features import Features

__all__ = [
    "FEATURE_OPTIONS",
    "VIEW_ROW_COLUMNS",
    "IndexDiff",
    "IndexedModel",
    "LiveIndex",
    "LoadReport",
    "StaleFeatures",
    "StaleView",
    "ViewRow",
    "load_live_index",
]

log = logging.getLogger(__name__)


class StaleFeatures(VisionCellError):
    """Stored features come from another descriptor method or version than the index uses."""

    code = "stale_features"


#: How long a view added by this process is kept although a database snapshot lacks it
#: (``add_views`` indexes views just before its transaction commits), seconds.
LOCAL_GRACE_S = 30.0

#: Stored images read at a time when the index is built (:meth:`LiveIndex.load`).
IMAGE_CHUNK = 64


class LiveIndex(IndexCore):
    """The in-memory index of every trained view, kept in step with the database.

    Parameters
    ----------
    method : str
        Feature method of every view (:func:`vision.features.extract`).
    max_features : int
        Strongest keypoints kept per view.
    transfer : (str, str)
        The camera's transfer curve (``"linear"`` or ``"srgb"``) for the colour descriptor
        of a colour method (an option of its extraction, so part of the descriptor version:
        views extracted with another curve are stale) and for the colour tie-break
        (``Settings.resolved_camera_transfer``).
    """

    def check_features(self, kind: str, version: str, *, what: str = "the features") -> None:
        """Raise :class:`StaleFeatures` unless ``kind``/``version`` match what the index uses."""
        if kind != self.method or version != self.version:
            raise StaleFeatures(
                f"{what} were extracted with {kind!r} version {version!r}; this VisionCell "
                f"uses {self.method!r} version {self.version!r}: re-extract them from the "
                "stored images with `visioncell models reextract`"
            )

    # -- building -----------------------------------------------------------------------
    async def load(self, db: Database) -> LoadReport:
        """Fill the (empty) index from every model and trained view in the database."""
        t0 = time.perf_counter()
        async with db.session() as session:
            models = list(await session.scalars(select(ObjectModel)))
            rows = (await session.execute(select(*VIEW_ROW_COLUMNS).order_by(TrainedView.id))).all()
            by_id = {m.id: IndexedModel.of(m) for m in models}
            with self._lock:
                if len(self._index):
                    raise RuntimeError("LiveIndex.load() fills an empty index only")
                self._models = dict(by_id)
                for row in rows:
                    self._index_row(by_id[row[1]], tuple(row))  # type: ignore[arg-type]
            # The views' images, a chunk at a time (not every image in memory at once):
            # side views' colour signatures (the twins' tie-break) and the belt's colour
            # round each top view (the light it was taught under).
            images = await session.stream(
                select(TrainedView.id, TrainedView.image_png, TrainedView.mask_png)
                .order_by(TrainedView.id)
                .execution_options(yield_per=IMAGE_CHUNK)
            )  # fmt: skip
            async for part in images.partitions(IMAGE_CHUNK):
                with self._lock:
                    for vid, png, mask_png in part:
                        self._colour_from_png(vid, png, mask_png)
        self._changed()
        with self._lock:
            self._generation += 1
            report = LoadReport(
                len(by_id),
                len(self._view_model),
                tuple(self._stale.values()),
                time.perf_counter() - t0,
            )
        if report.stale:
            log.warning(
                "%d trained views left out of the index: %s",
                len(report.stale),
                report.stale[0].reason,
            )
        return report

    def _index_row(self, model: IndexedModel, row: ViewRow) -> bool:
        """Index one stored view (lock held), or list it as stale; True if indexed."""
        vid, mid, viewpoint, blob, kind, version = row
        try:
            self.check_features(kind, version, what=f"view {vid} of {model.name!r}")
            feats = Features.from_bytes(blob)
            self._index.add(
                model.name,
                feats,
                viewpoint=viewpoint,
                part=model.part,
                base=model.sitting_base,
                view_id=vid,
            )
        except (ValueError, VisionCellError) as exc:
            reason = getattr(exc, "detail", str(exc))
            self._stale[vid] = StaleView(vid, mid, kind, version, reason)
            return False
        self._view_model[vid] = mid
        return True

    # -- changes made by other processes ---------------------------------------------------
    def diff(
        self, models: dict[int, IndexedModel], views: dict[int, tuple[int, str, str]]
    ) -> IndexDiff:
        """What to change so that the index matches a snapshot of the database.

        ``models`` are every model row by id; ``views`` map every trained view's id to
        ``(model_id, descriptor_kind, descriptor_version)`` (no features: a cheap query).
        A view whose id is known but now belongs to another model, or was re-extracted
        with another descriptor version, is loaded again.
        """
        with self._lock:
            put = tuple(m for mid, m in sorted(models.items()) if self._models.get(mid) != m)
            drop = tuple(mid for mid in sorted(self._models) if mid not in models)
            now = time.monotonic()
            for vid in [v for v, t in self._added_at.items() if now - t >= LOCAL_GRACE_S]:
                del self._added_at[vid]
            known = set(self._view_model) | set(self._stale)
            missing = [v for v in known if v not in views]
            remove = tuple(sorted(v for v in missing if v not in self._added_at))
            deferred = len(remove) < len(missing)
            load = []
            for vid, (mid, kind, version) in sorted(views.items()):
                if mid not in models:
                    continue  # the model went between the two reads: the next sync sees it
                have = self._view_model.get(vid)
                if have is not None:
                    if have != mid or (kind, version) != (self.method, self.version):
                        load.append(vid)
                    continue
                st = self._stale.get(vid)
                if st is None or (st.model_id, st.descriptor_kind, st.descriptor_version) != (
                    mid,
                    kind,
                    version,
                ):
                    load.append(vid)
            return IndexDiff(self._generation, put, drop, remove, tuple(load), deferred)

    def apply(
        self,
        diff: IndexDiff,
        rows: list[ViewRow],
        images: Mapping[int, tuple[bytes, bytes | None]] | None = None,
    ) -> bool:
        """Apply ``diff`` with the stored ``rows`` of its :attr:`IndexDiff.load_views`
        (and the stored image and mask PNGs of its views, by view id: side views' colour
        signatures, top views' belt colour).

        Returns False, changing nothing, if the index took a change since the diff was
        taken (the snapshot may predate it: take a new diff).  Rows of views whose model
        the index does not know (deleted meanwhile) are skipped.
        """
        with self._lock:
            if self._generation != diff.generation:
                return False
            for vid in diff.remove_views:
                self.remove_view(vid)
            for mid in diff.drop_models:
                self.drop_model(mid)
            for m in diff.put_models:
                self.put_model(m)
            for row in rows:
                model = self._models.get(row[1])
                if model is None:
                    continue
                self.remove_view(row[0])
                if self._index_row(model, row) and images and row[0] in images:
                    self._colour_from_png(row[0], *images[row[0]])
            self._generation += 1
        # A sync that found the database as this index already is (this process's own
        # writes move the change counter too) changed nothing: telling the listeners would
        # stop the threshold choice running over these very views, again and again.
        if not diff.empty:
            self._changed()
        return True

    def add_view(
        self,
        model: IndexedModel,
        view_id: int,
        viewpoint: int,
        features: Features,
        *,
        image: NDArray[np.uint8] | None = None,
        mask: NDArray[np.bool_] | None = None,
    ) -> None:
        """Index one stored view (its features must be of the index's method and version);
        a view already indexed under this id is replaced.  With the view's RGB ``image``
        (and ``mask``), a side view also gets its colour signature (:func:`colour_of`) and
        a top view its belt colour (:meth:`light_reference`)."""
        colour, outline = colour_of(
            viewpoint, features, image, mask, transfer=self._index.colour_transfer
        )
        if features.method != self.method or features.version != self.feature_version:
            self.check_features(features.method, features.version, what=f"view {view_id}")
        with self._lock:
            self._generation += 1
            if view_id in self._view_model:
                self._index.remove_view(view_id)
                del self._view_model[view_id]
            self._belt.pop(view_id, None)
            self._models[model.id] = model
            self._added_at[view_id] = time.monotonic()
            try:
                self._index.add(
                    model.name,
                    features,
                    viewpoint=viewpoint,
                    part=model.part,
                    base=model.sitting_base,
                    view_id=view_id,
                    colour=colour,
                    outline=outline,
                )
            except ValueError as exc:
                raise InvalidInput(str(exc)) from exc
            self._view_model[view_id] = model.id
            self._stale.pop(view_id, None)
            if viewpoint == 1:
                self._set_belt(view_id, image, mask)
        self._changed()


async def load_live_index(db: Database, settings: Any) -> LiveIndex:
    """Build the live index of ``settings``' feature method from the database (at start-up)."""
    import asyncio

    live = await asyncio.to_thread(
        LiveIndex,
        method=settings.recognition_method,
        max_features=settings.recognition_max_features,
        transfer=settings.resolved_camera_transfer(),
    )
    report = await live.load(db)
    log.info(
        "recognition index: %d views of %d models in %.2f s (%d stale)",
        report.views,
        report.models,
        report.seconds,
        len(report.stale),
    )
    return live
