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
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable, Iterator, Mapping
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray
from sqlalchemy import select

from backend.db.models import ObjectModel, TrainedView
from backend.db.session import Database
from backend.recognition import images as im
from vision.errors import InvalidInput, VisionCellError
from vision.features import Features
from vision.recognition import ViewIndex
from vision.recognition.index import view_colour, view_outline
from vision.recognition.light import surround_colour

__all__ = [
    "IndexDiff",
    "IndexedModel",
    "LiveIndex",
    "LoadReport",
    "StaleFeatures",
    "StaleView",
    "load_live_index",
]

log = logging.getLogger(__name__)


class StaleFeatures(VisionCellError):
    """Stored features come from another descriptor method or version than the index uses."""

    code = "stale_features"


@dataclass(frozen=True)
class IndexedModel:
    """What the index keeps about a model (from its database row)."""

    id: int
    name: str
    part: str
    sitting_base: str
    kind: str
    threshold: float | None
    """The model's own threshold (engineer's override), None for the automatic one."""
    height_m: float | None = None
    """Height above the sitting base, metres (stored with the model; None: not known)."""
    grasp_obj: tuple[float, float, float] | None = None
    """Suction point on the upper surface, object frame, metres (None: not stored)."""
    geometry_source: str = ""
    """``measured`` (by the teach: the pick searches near the height), ``entered`` (by an
    engineer: the pick goes to it) or empty (none stored)."""

    @classmethod
    def of(cls, row: ObjectModel) -> IndexedModel:
        from backend.recognition.models import grasp_of

        return cls(row.id, row.name, row.part, row.sitting_base, row.kind.value, row.threshold,
                   row.height_m, grasp_of(row), row.geometry_source or "")  # fmt: skip


@dataclass(frozen=True)
class StaleView:
    """A stored view left out of the index because its features are stale."""

    view_id: int
    model_id: int
    descriptor_kind: str
    descriptor_version: str
    reason: str


@dataclass(frozen=True)
class LoadReport:
    """Outcome of building the index from the database."""

    models: int
    views: int
    stale: tuple[StaleView, ...]
    seconds: float


#: Extraction options per method beyond the engine's own.  Options given here become part
#: of the stored descriptor version (views extracted without them are listed as stale, to
#: be re-extracted from their stored images).  No fixed ``threshold``: ``ViewIndex`` halves
#: the detector threshold on low-texture views, which raised the gear housing's top view
#: from 13 SIFT features to 42 in the simulated cell.  ``smooth_px``: a 1 px
#: Gaussian before SIFT, because renders without optical blur and sensor noise near that
#: lowered threshold gave first-octave keypoints that did not survive a turn of the part on
#: the belt (``benchmarks/recognition_yaw_curve.py``, five parts taught at yaw 0 and seen at
#: 15..90 deg in a new frame: median score 0.08 before, 0.17 after; the pipe flange, whose
#: fine bolt holes the blur removes, 0.43 -> 0.08; in the same diagnostic 1 px beat 0.7 and
#: 1.4 px on the gear housing and the valve block; ``benchmarks/recognition_yaw.py`` without
#: the colour tie-break: 66.7 -> 70.8 % named with 0.7, 1.0 and 1.4 px alike).
FEATURE_OPTIONS: dict[str, dict[str, float]] = {"sift": {"smooth_px": 1.0}}


def colour_of(
    viewpoint: int,
    features: Features,
    image: NDArray[np.uint8] | None,
    mask: NDArray[np.bool_] | None,
    *,
    transfer: str = "srgb",
) -> tuple[NDArray[np.float32] | None, NDArray[np.float32] | None]:
    """``(signature, outline)`` of a side view's object region in its RGB ``image``
    (:func:`vision.recognition.index.view_colour`), ``(None, None)`` for a top view, a grey
    or absent image, or a region without usable colour.  Only side views need one: the
    colour tie-break of :func:`vision.recognition.recognise_views` compares side views."""
    if viewpoint not in (2, 3) or image is None or image.ndim != 3:
        return None, None
    m = None if mask is None else mask.astype(np.uint8)
    outline = view_outline(features, m)
    colour = view_colour(image, outline, mask=m, transfer=transfer)
    return (None, None) if colour is None else (colour, outline)


def _probe_image() -> NDArray[np.uint8]:
    rng = np.random.default_rng(7)
    img = rng.integers(0, 256, size=(24, 24), dtype=np.uint8)
    return np.kron(
        img, np.ones((4, 4), dtype=np.uint8)
    )  # 96 x 96 blocks: corners for every detector


@dataclass(frozen=True)
class IndexDiff:
    """What separates the index from a snapshot of the database (:meth:`LiveIndex.diff`)."""

    generation: int
    """The index's change count when the diff was taken (:meth:`LiveIndex.apply` checks it)."""
    put_models: tuple[IndexedModel, ...]
    drop_models: tuple[int, ...]
    remove_views: tuple[int, ...]
    load_views: tuple[int, ...]
    """Views to (re)load from the database: new ones, re-extracted ones, reused ids."""
    deferred: bool = False
    """Views added here in the last :data:`LOCAL_GRACE_S` were missing from the snapshot and
    kept (their transaction may not have committed yet): diff again later."""

    @property
    def empty(self) -> bool:
        return not (self.put_models or self.drop_models or self.remove_views or self.load_views)


#: How long a view added by this process is kept although a database snapshot lacks it
#: (``add_views`` indexes views just before its transaction commits), seconds.
LOCAL_GRACE_S = 30.0

#: Stored images read at a time when the index is built (:meth:`LiveIndex.load`).
IMAGE_CHUNK = 64

#: A stored view as :meth:`LiveIndex.apply` takes it:
#: ``(view_id, model_id, viewpoint, features blob, descriptor kind, descriptor version)``.
ViewRow = tuple[int, int, int, bytes, str, str]
#: The columns of a :data:`ViewRow`, in its order (for ``select(*VIEW_ROW_COLUMNS)``).
VIEW_ROW_COLUMNS = (
    TrainedView.id,
    TrainedView.model_id,
    TrainedView.viewpoint,
    TrainedView.features,
    TrainedView.descriptor_kind,
    TrainedView.descriptor_version,
)


class LiveIndex:
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

    def __init__(
        self,
        *,
        method: str = "sift",
        max_features: int = 1000,
        transfer: tuple[str, str] = ("linear", "srgb"),
    ) -> None:
        options: dict[str, Any] = dict(FEATURE_OPTIONS.get(method, {}))
        descriptor, tiebreak = transfer
        if descriptor not in ("linear", "srgb"):
            raise ValueError(f"transfer must be 'linear' or 'srgb', got {descriptor!r}")
        if method.startswith("color-") and descriptor != "linear":
            options["transfer"] = descriptor  # linear is the extraction's own default
        self._index = ViewIndex(
            method, max_features=max_features, feature_options=options, colour_transfer=tiebreak
        )
        self._lock = threading.RLock()
        self._models: dict[int, IndexedModel] = {}
        self._view_model: dict[int, int] = {}
        self._stale: dict[int, StaleView] = {}
        #: The belt's colour round the object in each indexed top view (the light it was
        #: taught under, :func:`vision.recognition.light.surround_colour`).
        self._belt: dict[int, NDArray[np.float64]] = {}
        #: Count of changes made through the change methods (see :meth:`apply`).
        self._generation = 0
        #: When this process added each recent view (``time.monotonic()``), see :meth:`diff`.
        self._added_at: dict[int, float] = {}
        #: Called (from whichever thread made it) after every change, lock released.
        self._listeners: list[Callable[[], None]] = []
        # The descriptor version this build extracts (changes with OpenCV, a PCA basis...),
        # with the extraction options that change what is extracted (stored per view).
        probe = _probe_image()
        if method.startswith("color-"):  # the colour methods describe RGB images only
            probe = np.repeat(probe[..., None], 3, axis=2)
        self.feature_version = self._index.features(probe).version
        # (the transfer curve by its name alone: the column holds 32 characters)
        tag = ",".join(
            str(v) if k == "transfer" else f"{k}={v}" for k, v in sorted(options.items())
        )
        self.version = self.feature_version + (f";{tag}" if tag else "")
        if len(self.version) > 32:  # the database column
            raise ValueError(f"descriptor version tag {self.version!r} is over 32 characters")

    # -- change listeners ---------------------------------------------------------------
    def add_listener(self, fn: Callable[[], None]) -> None:
        """Call ``fn()`` after every change of the index (a view added, removed or
        re-indexed, a model put or dropped, a sync applied), from the thread that made it;
        ``fn`` must be quick and thread-safe (hand the news to an event loop)."""
        self._listeners.append(fn)

    def remove_listener(self, fn: Callable[[], None]) -> None:
        """Stop calling ``fn``."""
        if fn in self._listeners:
            self._listeners.remove(fn)

    def _changed(self) -> None:
        for fn in list(self._listeners):
            try:
                fn()
            except Exception:  # a broken listener must not break a change
                log.exception("live index listener failed")

    # -- reading ------------------------------------------------------------------------
    @property
    def method(self) -> str:
        """Feature method of the index."""
        return self._index.method

    def __len__(self) -> int:
        with self._lock:
            return len(self._index)

    @contextmanager
    def reading(self) -> Iterator[ViewIndex]:
        """Hold the lock and yield the index (do not keep it beyond the ``with``)."""
        with self._lock:
            yield self._index

    def light_reference(self) -> NDArray[np.float64] | None:
        """The belt's colour under the light the views were taught under: the per-channel
        median over the indexed top views that have one (None without any).  Inspections
        scale a query's channels by its ratio to the belt's colour now
        (:func:`vision.recognition.light.light_gain`)."""
        with self._lock:
            if not self._belt:
                return None
            return np.median(np.stack(list(self._belt.values())), axis=0)

    def model(self, model_id: int) -> IndexedModel | None:
        """What the index knows about a model (None if it holds no entry for it)."""
        with self._lock:
            return self._models.get(model_id)

    def models(self) -> dict[int, IndexedModel]:
        """Every model the index knows, by id."""
        with self._lock:
            return dict(self._models)

    def model_of_name(self, name: str) -> IndexedModel | None:
        """The model called ``name`` (None if unknown)."""
        with self._lock:
            return next((m for m in self._models.values() if m.name == name), None)

    def views_of(self, model_id: int) -> list[int]:
        """Ids of the indexed views of a model."""
        with self._lock:
            return sorted(v for v, m in self._view_model.items() if m == model_id)

    def has_view(self, view_id: int) -> bool:
        with self._lock:
            return view_id in self._view_model

    @property
    def generation(self) -> int:
        """How many changes the index has taken (grows with every change method)."""
        with self._lock:
            return self._generation

    @property
    def stale(self) -> dict[int, StaleView]:
        """Stored views refused because of their descriptor version, by view id."""
        with self._lock:
            return dict(self._stale)

    # -- features -----------------------------------------------------------------------
    def extract(self, image: NDArray[np.uint8], mask: NDArray[np.bool_] | None) -> Features:
        """Features of ``image`` inside ``mask`` with the index's method and options."""
        return self._index.features(image, mask=None if mask is None else mask.astype(np.uint8))

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

    def _colour_from_png(self, view_id: int, png: bytes, mask_png: bytes | None) -> None:
        """Give an indexed view what its stored image says of colour (lock held): a side
        view its colour signature, a top view the belt's colour round the object."""
        if view_id not in self._view_model:
            return
        view = self._index.view(view_id)
        try:
            rgb = im.rgb_from_png(png)
            mask = None if mask_png is None else im.mask_from_png(mask_png)
        except (ValueError, VisionCellError) as exc:
            log.warning("view %d: no colour signature (%s)", view_id, exc)
            return
        if view.viewpoint == 1:
            self._set_belt(view_id, rgb, mask)
            return
        colour, outline = colour_of(
            view.viewpoint, view.features, rgb, mask, transfer=self._index.colour_transfer
        )
        if colour is not None and outline is not None:
            self._index.set_colour(view_id, colour, outline)

    def _set_belt(
        self, view_id: int, rgb: NDArray[np.uint8] | None, mask: NDArray[np.bool_] | None
    ) -> None:
        """Keep a top view's belt colour (lock held); none without an RGB image and mask."""
        self._belt.pop(view_id, None)
        if rgb is None:
            return
        try:
            belt = surround_colour(rgb, mask)
        except VisionCellError as exc:
            log.warning("view %d: no belt colour (%s)", view_id, exc)
            return
        if belt is not None:
            self._belt[view_id] = belt

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

    # -- changes (call after the database accepted them) ----------------------------------
    def put_model(self, model: IndexedModel) -> None:
        """Add or update a model's entry; views follow a rename or a new part or base."""
        with self._lock:
            self._generation += 1
            old = self._models.get(model.id)
            self._models[model.id] = model
            same = (model.name, model.part, model.sitting_base)
            if old is None or (old.name, old.part, old.sitting_base) == same:
                return
            for vid in self.views_of(model.id):
                view = self._index.view(vid)
                self._index.remove_view(vid)
                self._index.add(
                    model.name,
                    view.features,
                    viewpoint=view.viewpoint,
                    part=model.part,
                    base=model.sitting_base,
                    view_id=vid,
                    colour=view.colour,
                    outline=view.outline,
                )
        self._changed()

    def drop_model(self, model_id: int) -> int:
        """Forget a model and its views; return how many views left the index."""
        with self._lock:
            self._generation += 1
            model = self._models.pop(model_id, None)
            gone = self.views_of(model_id)
            for vid in gone:
                self._index.remove_view(vid)
                del self._view_model[vid]
                self._belt.pop(vid, None)
            for vid in [v for v, s in self._stale.items() if s.model_id == model_id]:
                del self._stale[vid]
            if model is not None:
                assert not self._index.views_of(model.name)
        self._changed()
        return len(gone)

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

    def remove_view(self, view_id: int) -> bool:
        """Take one view out of the index; False if it was not in it."""
        with self._lock:
            self._generation += 1
            self._stale.pop(view_id, None)
            self._belt.pop(view_id, None)
            if view_id not in self._view_model:
                return False
            self._index.remove_view(view_id)
            del self._view_model[view_id]
        self._changed()
        return True


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
