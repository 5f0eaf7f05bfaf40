"""The in-memory side of the live index (:mod:`backend.recognition.index`): its state, the
feature extraction options, reading it under its lock, the change listeners, the colour
of views, and the changes that take no stored features in."""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any

import numpy as np
from numpy.typing import NDArray

from backend.recognition import images as im
from backend.recognition.indextypes import IndexedModel, StaleView
from vision.errors import VisionCellError
from vision.features import Features
from vision.recognition import ViewIndex
from vision.recognition.index import view_colour, view_outline
from vision.recognition.light import surround_colour

log = logging.getLogger(__name__)

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


class IndexCore:
    """The live index's state, its reading side and its listeners, and the changes that
    take no stored features in (a model put or dropped, a view removed); the features
    themselves come in through :class:`~backend.recognition.index.LiveIndex`."""

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
