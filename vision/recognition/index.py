"""The index of trained views (chapter section 3.5): models, viewpoints, features, and a
versioned byte form for the database.

A trained view is one image of one model from one viewpoint (1 = top, 2 and 3 = the side
positions of section 3.5.3), reduced to its local features. A physical part that can sit on
several bases is trained as one model per base (section 3.5.3): ``part`` and ``base`` are kept
beside the model name so that reports can group them. Retrieval over all descriptors is the
job of :mod:`vision.recognition.search`; the index only owns the views and hands out cached
searchers.
"""

from __future__ import annotations

import dataclasses
import json
from collections.abc import Iterable
from typing import Literal, overload

import cv2
import numpy as np

from vision.features import METHODS, Features, extract
from vision.recognition import serial
from vision.recognition.colour import check_signature, colour_signature, region_from_outline
from vision.recognition.search import Searcher
from vision.recognition.serial import FORMAT, FORMAT_VERSION, IndexFormatError
from vision.recognition.trained import VIEWPOINTS, TrainedView, check_viewpoint

__all__ = [
    "FORMAT",
    "FORMAT_VERSION",
    "MAX_FEATURES_PER_VIEW",
    "MAX_VIEWS",
    "VIEWPOINTS",
    "IndexFormatError",
    "TrainedView",
    "ViewIndex",
    "check_image",
    "check_outline",
    "check_viewpoint",
    "view_colour",
    "view_outline",
]

#: Viewpoints of the cell: 1 = top, 2 and 3 = the two side positions (section 3.5.3).
#: Caps that keep one index within memory and the ANN build within a second or two.
MAX_VIEWS = 50_000
MAX_FEATURES_PER_VIEW = 4_000
MAX_NAME_CHARS = 200
#: Strongest keypoints kept per image unless the caller says otherwise.
DEFAULT_MAX_FEATURES = 1_000
#: Adaptive detection: an image with fewer features than this is described again with half
#: the detector threshold (at most :data:`ADAPT_STEPS` times). A verified view scores near
#: saturation only with some 60 inliers (``N_SAT`` of the registration score), which needs
#: roughly twice as many features; plain, low-texture parts (and small images) give fewer
#: at the detectors' default thresholds.
DEFAULT_MIN_FEATURES = 80
ADAPT_STEPS = 2
#: Default detector thresholds of the methods that adapt (OpenCV's defaults).
_DEFAULT_DETECTOR_THRESHOLD = {"sift": 0.04, "akaze": 0.001}

#: Methods whose features inside a mask come out the same when the image is cropped round
#: the mask (:func:`_mask_crop`): their detector and descriptor look at a bounded
#: neighbourhood, and their pyramid halves the image per octave, so a crop whose corner
#: sits on the octave grid samples every octave at the same pixels.  Not the colour
#: methods (their noise weights are measured over the whole image), ORB (a 1.2 pyramid)
#: or AKAZE (a nonlinear diffusion over the whole image).
CROP_METHODS = frozenset({"sift", "surf"})
#: Context kept round the mask's bounding box, pixels: a descriptor's support reaches past
#: the keypoint (a SIFT descriptor's window is about 5.3 keypoint diameters wide: 3 sigma
#: per cell, 4 cells and one for interpolation, rotated), so a keypoint of up to about 12 px
#: near the mask's edge keeps its exact descriptor; larger ones there see the crop's edge.
CROP_MARGIN_PX = 64
#: The crop's corner is put on a multiple of this (2^5: the first five octaves' grids).
CROP_ALIGN_PX = 32
#: Crop only when the crop holds at most this share of the image (else it saves little).
CROP_MAX_SHARE = 0.6


def _mask_crop(mask: np.ndarray) -> tuple[slice, slice] | None:
    """Rows and columns of the image round ``mask`` that extraction needs, or None.

    A query region is about 15 % of the frame (side views) or less (a part on the belt from
    the top), and SIFT's cost grows with the image it builds its pyramid over (doubled for
    the first octave, Lowe 2004, 3.3): detecting in the crop is 3-4x cheaper, and with the
    crop's corner on the octave grid the keypoints and descriptors are the whole image's
    (``benchmarks.features_crop``, 40 taught views of the twelve parts: median 100 % of the
    keypoints at the same place, at least 88 %, 96 % of them with the same descriptor, the
    others large keypoints near the crop's edge; 39 against 104 ms of CPU in median; with
    the corner off the grid only 90 % of the keypoints were found again).
    """
    ys, xs = np.nonzero(mask)
    if xs.size == 0:
        return None
    h, w = mask.shape
    y0 = max(0, (int(ys.min()) - CROP_MARGIN_PX) // CROP_ALIGN_PX * CROP_ALIGN_PX)
    x0 = max(0, (int(xs.min()) - CROP_MARGIN_PX) // CROP_ALIGN_PX * CROP_ALIGN_PX)
    y1 = min(h, int(ys.max()) + 1 + CROP_MARGIN_PX)
    x1 = min(w, int(xs.max()) + 1 + CROP_MARGIN_PX)
    if (y1 - y0) * (x1 - x0) > CROP_MAX_SHARE * h * w:
        return None
    return slice(y0, y1), slice(x0, x1)


@overload
def _check_name(value: object, name: str, *, optional: Literal[False] = False) -> str: ...
@overload
def _check_name(value: object, name: str, *, optional: bool) -> str | None: ...
def _check_name(value: object, name: str, *, optional: bool = False) -> str | None:
    if value is None and optional:
        return None
    if not isinstance(value, str) or not value.strip():
        raise ValueError(f"{name} must be a non-empty string, got {value!r}")
    if len(value) > MAX_NAME_CHARS:
        raise ValueError(f"{name} must be at most {MAX_NAME_CHARS} characters, got {len(value)}")
    return value


def check_image(image: object, mask: object = None) -> tuple[np.ndarray, np.ndarray | None]:
    """Validate an RGB (H, W, 3) or grey (H, W) uint8 image and an optional (H, W) mask.

    The mask may be bool or uint8 (non-zero = object); it must cover at least one pixel.
    """
    if not isinstance(image, np.ndarray):
        raise ValueError(f"image must be a numpy array or Features, got {type(image).__name__}")
    if image.dtype != np.uint8:
        raise ValueError(f"image must be uint8, got dtype {image.dtype}")
    if image.ndim not in (2, 3) or (image.ndim == 3 and image.shape[2] != 3):
        raise ValueError(f"image must have shape (H, W) or (H, W, 3), got {image.shape}")
    if min(image.shape[:2]) < 16 or max(image.shape[:2]) > 8192:
        raise ValueError(f"image sides must be within 16..8192 px, got {image.shape[:2]}")
    if mask is None:
        return image, None
    if not isinstance(mask, np.ndarray) or mask.dtype not in (np.bool_, np.uint8):
        raise ValueError(f"mask must be a bool or uint8 array, got {getattr(mask, 'dtype', mask)}")
    if mask.shape != image.shape[:2]:
        raise ValueError(f"mask shape {mask.shape} differs from the image's {image.shape[:2]}")
    m = mask > 0
    if not m.any():
        raise ValueError("mask is empty: it selects no pixel of the image")
    return image, m.astype(np.uint8)


#: Vertices kept of a view's region outline (the convex hull, simplified beyond this).
MAX_OUTLINE_POINTS = 64


def view_outline(features: Features, mask: np.ndarray | None = None) -> np.ndarray:
    """Outline of a trained view's region, (K, 2) float32 pixels: the convex hull of the
    ``mask`` when given (the whole object, so a colour band at its edge is inside), else of
    the keypoints; at most :data:`MAX_OUTLINE_POINTS` vertices."""
    pts = features.keypoints.xy
    if mask is not None:
        m = (np.asarray(mask) > 0).astype(np.uint8)
        contours, _ = cv2.findContours(m, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)
        if contours:
            pts = np.concatenate([c.reshape(-1, 2) for c in contours]).astype(np.float64)
    if len(pts) < 3:
        return np.zeros((0, 2), np.float32)
    hull = cv2.convexHull(np.ascontiguousarray(pts, dtype=np.float32))
    eps = 0.5
    while len(hull) > MAX_OUTLINE_POINTS:
        hull = cv2.approxPolyDP(hull, eps, True)
        eps *= 2.0
    return hull.reshape(-1, 2).astype(np.float32)


def check_outline(outline: object) -> np.ndarray:
    """Validate an outline: (K, 2) finite pixels, K at most :data:`MAX_OUTLINE_POINTS`."""
    a = np.asarray(outline, dtype=np.float32)
    if a.ndim != 2 or a.shape[1] != 2 or len(a) > MAX_OUTLINE_POINTS:
        raise ValueError(
            f"an outline has shape (K, 2) with K <= {MAX_OUTLINE_POINTS}, got {a.shape}"
        )
    if not np.all(np.isfinite(a)):
        raise ValueError("an outline must be finite")
    return a


def view_colour(
    image: np.ndarray,
    outline: np.ndarray,
    *,
    mask: np.ndarray | None = None,
    H: np.ndarray | None = None,
    transfer: str = "srgb",
) -> np.ndarray | None:
    """Colour signature (:func:`vision.recognition.colour.colour_signature`) of a view's region.

    The region is the convex polygon ``outline`` (:func:`view_outline`) in ``image``, inside
    ``mask`` when given; for a query, pass the trained view's outline and the
    trained-view-to-query map ``H``: the outline is mapped into the query, so both
    signatures describe the same part of the object. ``None`` when the region has too few
    usable pixels or the image is grey.  ``transfer`` is the camera's transfer curve
    (``"srgb"`` or ``"linear"``).
    """
    if image.ndim != 3:
        return None
    region = region_from_outline(outline, image.shape[:2], H)
    if mask is not None:
        region &= (np.asarray(mask) > 0).astype(np.uint8)
    return colour_signature(image, region, transfer=transfer)


def _viewpoints(viewpoint: int | tuple[int, ...]) -> tuple[int, ...]:
    """One viewpoint or a non-empty tuple of them, checked."""
    if isinstance(viewpoint, tuple):
        if not viewpoint or len(viewpoint) > len(VIEWPOINTS):
            raise ValueError(f"viewpoints must be 1 to 3 of {VIEWPOINTS}, got {viewpoint!r}")
        return tuple(check_viewpoint(v) for v in viewpoint)
    return (check_viewpoint(viewpoint),)


class ViewIndex:
    """Trained views of every model, with cached approximate-nearest-neighbour searchers.

    Parameters
    ----------
    method : str
        Feature method of every view and query (see :func:`vision.features.extract`).
    max_features : int
        Strongest keypoints kept per image (1..:data:`MAX_FEATURES_PER_VIEW`).
    geometry : {"affine", "homography"}
        Model fitted by the verification (:func:`vision.registration.verify`). Affine is the
        default: measured on COIL-20 (benchmarks/recognition.py) it verifies more views of
        3D objects than the 8-dof homography from a few dozen features; both give a 3x3
        matrix mapping trained-view pixels to query pixels.
    feature_options : dict, optional
        Further options for :func:`vision.features.extract` (``threshold``, ``upright``...).
    min_features : int
        Adaptive detection for ``"sift"`` and ``"akaze"`` (0 disables it): an image giving
        fewer features is described again with half the detector threshold, at most twice
        (:data:`DEFAULT_MIN_FEATURES`). Not applied when ``feature_options`` fixes
        ``threshold``. Trained views and queries go through the same rule.
    colour_transfer : {"srgb", "linear"}
        The cameras' transfer curve, for the views' and the queries' colour signatures
        (:func:`view_colour`, the tie-break of :func:`vision.recognition.recognise_views`).
        The colour descriptor's own (``color-sift``) is ``feature_options["transfer"]``.

    Examples
    --------
    >>> index = ViewIndex(method="sift")  # doctest: +SKIP
    >>> vid = index.add("wheel-a", top_image, viewpoint=1, mask=top_mask)  # doctest: +SKIP
    """

    def __init__(
        self,
        method: str = "sift",
        *,
        max_features: int = DEFAULT_MAX_FEATURES,
        geometry: str = "affine",
        feature_options: dict | None = None,
        min_features: int = DEFAULT_MIN_FEATURES,
        colour_transfer: str = "srgb",
    ) -> None:
        if method not in METHODS:
            raise ValueError(f"unknown feature method {method!r}; choose one of {METHODS}")
        if (
            isinstance(max_features, bool)
            or not isinstance(max_features, int)
            or not 1 <= max_features <= MAX_FEATURES_PER_VIEW
        ):
            raise ValueError(
                f"max_features must be an int in 1..{MAX_FEATURES_PER_VIEW}, got {max_features!r}"
            )
        if geometry not in ("affine", "homography"):
            raise ValueError(f"geometry must be 'affine' or 'homography', got {geometry!r}")
        options = dict(feature_options or {})
        for bad in ("mask", "max_features"):
            if bad in options:
                raise ValueError(f"feature_options must not set {bad!r}: pass it directly")
        json.dumps(options)  # options must survive serialisation
        if (
            isinstance(min_features, bool)
            or not isinstance(min_features, int)
            or not 0 <= min_features <= MAX_FEATURES_PER_VIEW
        ):
            raise ValueError(
                f"min_features must be an int in 0..{MAX_FEATURES_PER_VIEW}, got {min_features!r}"
            )
        if colour_transfer not in ("srgb", "linear"):
            raise ValueError(f"colour_transfer must be 'srgb' or 'linear', got {colour_transfer!r}")
        #: The cameras' transfer curve for the views' colour signatures (the tie-break).
        self.colour_transfer = colour_transfer
        self.min_features = min(min_features, max_features)
        self.method = method
        self.max_features = max_features
        self.geometry = geometry
        self.feature_options = options
        self._views: dict[int, TrainedView] = {}
        self._next_id = 1
        self._searchers: dict[tuple, Searcher] = {}

    # ----------------------------------------------------------------- reading
    def __len__(self) -> int:
        return len(self._views)

    def __repr__(self) -> str:
        return (
            f"ViewIndex(method={self.method!r}, views={len(self)}, models={len(self.models)}, "
            f"geometry={self.geometry!r})"
        )

    @property
    def models(self) -> tuple[str, ...]:
        """Model names, sorted."""
        return tuple(sorted({v.model for v in self._views.values()}))

    @property
    def views(self) -> tuple[TrainedView, ...]:
        """Every trained view, in order of id."""
        return tuple(self._views[k] for k in sorted(self._views))

    def view(self, view_id: int) -> TrainedView:
        """The trained view with this id (``KeyError`` if there is none)."""
        try:
            return self._views[view_id]
        except KeyError:
            raise KeyError(f"no trained view with id {view_id!r}") from None

    def views_of(self, model: str, *, viewpoint: int | None = None) -> tuple[TrainedView, ...]:
        """Views of one model, optionally from one viewpoint only."""
        return tuple(
            v
            for v in self.views
            if v.model == model and (viewpoint is None or v.viewpoint == viewpoint)
        )

    def viewpoints_of(self, model: str) -> tuple[int, ...]:
        """Viewpoints that have at least one trained view of ``model``."""
        return tuple(sorted({v.viewpoint for v in self._views.values() if v.model == model}))

    # ----------------------------------------------------------------- features
    def features(self, image: np.ndarray | Features, *, mask: np.ndarray | None = None) -> Features:
        """Extract this index's features from an image (inside ``mask``), or check given ones.

        Given :class:`Features` must come from this index's method (and ``mask`` must then be
        ``None``: the caller already restricted them).
        """
        if isinstance(image, Features):
            if mask is not None:
                raise ValueError("mask must be None when Features are given (already extracted)")
            if image.method != self.method:
                raise ValueError(
                    f"features of method {image.method!r} given to an index of {self.method!r}"
                )
            if len(image) > MAX_FEATURES_PER_VIEW:
                raise ValueError(
                    f"at most {MAX_FEATURES_PER_VIEW} features per image, got {len(image)}"
                )
            return image
        image, m = check_image(image, mask)
        full_shape = image.shape[:2]
        crop = _mask_crop(m) if m is not None and self.method in CROP_METHODS else None
        if crop is not None:
            assert m is not None
            image = np.ascontiguousarray(image[crop])
            m = np.ascontiguousarray(m[crop])
        kw = dict(self.feature_options)
        if m is not None:
            kw["mask"] = m
        feats = extract(image, self.method, max_features=self.max_features, **kw)
        threshold = _DEFAULT_DETECTOR_THRESHOLD.get(self.method)
        if threshold is not None and "threshold" not in self.feature_options:
            for _ in range(ADAPT_STEPS):
                if len(feats) >= self.min_features:
                    break
                threshold /= 2.0
                feats = extract(
                    image, self.method, max_features=self.max_features, threshold=threshold, **kw
                )
        if crop is None:
            return feats
        offset = np.array([crop[1].start, crop[0].start], dtype=np.float64)
        kps = dataclasses.replace(feats.keypoints, xy=feats.keypoints.xy + offset)
        return dataclasses.replace(feats, keypoints=kps, image_shape=full_shape)

    # ----------------------------------------------------------------- editing
    def add(
        self,
        model: str,
        image: np.ndarray | Features,
        *,
        viewpoint: int = 1,
        mask: np.ndarray | None = None,
        part: str | None = None,
        base: str | None = None,
        view_id: int | None = None,
        colour: np.ndarray | None = None,
        outline: np.ndarray | None = None,
    ) -> int:
        """Train one view of ``model`` and return its view id.

        Parameters
        ----------
        model : str
            Model name (non-empty, at most 200 characters).
        image : ndarray (H, W[, 3]) uint8 or Features
            The trained image (RGB or grey), or features already extracted with this index's
            method (what the database stores).
        viewpoint : int
            1 (top), 2 or 3 (side positions).
        mask : ndarray (H, W) bool or uint8, optional
            Object region: features are detected only inside it.
        part, base : str, optional
            Physical part and sitting base this model stands for.
        view_id : int, optional
            Id to give the view (a database key); by default the next free one.
        colour : ndarray of shape (SIGNATURE_SIZE,), optional
            The view's colour signature (:func:`view_colour`), for views given as features;
            an RGB image gets its own when none is given.
        outline : ndarray of shape (K, 2), optional
            The region ``colour`` describes (:func:`view_outline`); default: the convex
            hull of ``mask`` (RGB images) or of the keypoints.

        Raises
        ------
        ValueError
            Bad image, mask, names or viewpoint; features of another method or version than
            the views already trained; an image without any feature; a taken view id.
        """
        model = _check_name(model, "model")
        part = _check_name(part, "part", optional=True)
        base = _check_name(base, "base", optional=True)
        viewpoint = check_viewpoint(viewpoint)
        if view_id is not None:
            if isinstance(view_id, bool) or not isinstance(view_id, int) or view_id < 1:
                raise ValueError(f"view_id must be a positive int, got {view_id!r}")
            if view_id in self._views:
                raise ValueError(f"view id {view_id} is already in the index")
        if len(self._views) >= MAX_VIEWS:
            raise ValueError(f"the index is full ({MAX_VIEWS} views)")
        feats = self.features(image, mask=mask)
        if outline is not None:
            outline = check_outline(outline)
        elif isinstance(image, np.ndarray) and image.ndim == 3 and colour is None:
            outline = view_outline(feats, mask)
        if colour is not None:
            colour = check_signature(colour)
            if outline is None:
                outline = view_outline(feats)
        elif isinstance(image, np.ndarray) and image.ndim == 3 and outline is not None:
            colour = view_colour(image, outline, mask=mask, transfer=self.colour_transfer)
        if colour is None:
            outline = None
        if len(feats) < 3:
            raise ValueError(
                f"only {len(feats)} {self.method} features in the view of {model!r}: "
                "too few to verify a match (need 3); use a larger or more textured image"
            )
        for other in self._views.values():
            f = other.features
            if (f.version, f.binary, f.dim) != (feats.version, feats.binary, feats.dim):
                raise ValueError(
                    f"features of version {feats.version!r} (dim {feats.dim}) differ from the "
                    f"index's {f.version!r} (dim {f.dim}): retrain every view"
                )
            break
        vid = self._next_id if view_id is None else view_id
        self._views[vid] = TrainedView(vid, model, viewpoint, part, base, feats, colour, outline)
        self._next_id = max(self._next_id, vid + 1)
        self._searchers.clear()
        return vid

    def set_colour(self, view_id: int, colour: np.ndarray, outline: np.ndarray) -> None:
        """Give a trained view its colour signature and the outline it describes (a view
        loaded from features alone, whose image is read later)."""
        view = self.view(view_id)
        self._views[view_id] = dataclasses.replace(
            view, colour=check_signature(colour), outline=check_outline(outline)
        )

    def remove_model(self, model: str) -> int:
        """Remove every view of ``model``; return how many were removed (0 if unknown)."""
        gone = [k for k, v in self._views.items() if v.model == model]
        for k in gone:
            del self._views[k]
        if gone:
            self._searchers.clear()
        return len(gone)

    def remove_view(self, view_id: int) -> None:
        """Remove one view (``KeyError`` if there is none)."""
        self.view(view_id)
        del self._views[view_id]
        self._searchers.clear()

    # ----------------------------------------------------------------- search
    def searcher(
        self, *, viewpoint: int | tuple[int, ...] | None, exclude_models: Iterable[str] = ()
    ) -> Searcher | None:
        """The cached ANN searcher over the views of ``viewpoint`` (one viewpoint, several, or
        ``None`` = all), leaving out ``exclude_models``; ``None`` when no view is left."""
        excl = frozenset(exclude_models)
        vps = None if viewpoint is None else frozenset(_viewpoints(viewpoint))
        key = (vps, excl)
        if key not in self._searchers:
            views = [
                v for v in self.views if (vps is None or v.viewpoint in vps) and v.model not in excl
            ]
            if not views:
                return None
            if len(self._searchers) > 64:  # leave-one-model-out sweeps: keep the cache bounded
                self._searchers.clear()
            self._searchers[key] = Searcher(views)
        return self._searchers[key]

    # ----------------------------------------------------------------- bytes
    @property
    def next_id(self) -> int:
        """The id the next view added without ``view_id`` gets."""
        return self._next_id

    def to_bytes(self) -> bytes:
        """Serialise the index (views and options, not the ANN structures) to bytes.

        The blob is a compressed ``.npz`` with a JSON header naming :data:`FORMAT` and
        :data:`FORMAT_VERSION` (:mod:`vision.recognition.serial`); :meth:`from_bytes`
        refuses any other.
        """
        return serial.dump(self)

    @classmethod
    def from_bytes(cls, blob: bytes) -> ViewIndex:
        """Rebuild an index from :meth:`to_bytes`.

        Raises
        ------
        IndexFormatError
            Not a serialised view index, or one of another format version (stale: retrain or
            migrate it).
        """
        return serial.load(cls, blob)
