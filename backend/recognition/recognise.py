"""Recognising uploaded images without the arm (the chapter's 2D recognition, section 3.5.1):
one image matched against every trained view of a viewpoint, a score per model against its
threshold, the decision, the outline of the matched view and the object's 2D pose in the
image.

The work for one image is :func:`recognise_upload`, a plain function of bytes (decode after
the header's size was checked, features, retrieval, verification, decision), meant to run
in a worker thread; the route runs it under a concurrency bound.  :func:`inspection_record`
turns a result into the inspection row that ``store=true`` writes (source ``upload``), so
reports and exports include uploaded images like the cell's own inspections.
"""

from __future__ import annotations

import math
import time
from collections.abc import Mapping
from dataclasses import dataclass, field
from datetime import datetime
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from backend.inspection.results import InspectionRecord, ViewRecord
from backend.recognition import images as im
from backend.recognition.index import LiveIndex
from vision.errors import InvalidInput
from vision.recognition import ThresholdChoice, recognise
from vision.recognition.index import view_outline

__all__ = [
    "POLICY",
    "ImagePose",
    "ImageRecognition",
    "ModelScore",
    "Region",
    "inspection_record",
    "recognise_upload",
]

#: The ``policy`` of a stored upload's inspection row: one image, one viewpoint.
POLICY = "image"


@dataclass(frozen=True)
class Region:
    """A rectangle of the image to look in, pixels (``x``, ``y`` of its top-left corner)."""

    x: int
    y: int
    width: int
    height: int

    def __post_init__(self) -> None:
        for k in ("x", "y", "width", "height"):
            v = getattr(self, k)
            if isinstance(v, bool) or not isinstance(v, int) or not 0 <= v <= im.MAX_IMAGE_SIDE:
                raise InvalidInput(
                    f"region {k} must be an int in 0..{im.MAX_IMAGE_SIDE}, got {v!r}"
                )
        if self.width < 16 or self.height < 16:
            raise InvalidInput(
                f"the region must be at least 16 x 16 px, got {self.width} x {self.height}"
            )

    def mask(self, shape: tuple[int, int]) -> NDArray[np.bool_]:
        """The region as a boolean mask of an image of ``shape`` (H, W)."""
        h, w = shape
        if self.x + self.width > w or self.y + self.height > h:
            raise InvalidInput(
                f"the region {self.x},{self.y} {self.width} x {self.height} px leaves the "
                f"{w} x {h} px image"
            )
        m = np.zeros((h, w), dtype=bool)
        m[self.y : self.y + self.height, self.x : self.x + self.width] = True
        return m


@dataclass(frozen=True)
class ModelScore:
    """One model's score against the threshold it must pass."""

    model: str
    score: float
    """Registration score in [0, 1]."""
    threshold: float
    """The model's threshold at the viewpoint (its own, the automatic per-model, or global)."""

    @property
    def passed(self) -> bool:
        """Whether the score is above the threshold (strictly, as the decision reads it)."""
        return self.score > self.threshold


@dataclass(frozen=True)
class ImagePose:
    """The matched view's placement in the image: the similarity closest to its map."""

    x_px: float
    """Image column of the matched view's outline centre, pixels."""
    y_px: float
    """Image row of the matched view's outline centre, pixels."""
    angle_rad: float
    """Turn from the trained view to the image, radians (counter-clockwise on screen is
    negative: image rows grow downwards)."""
    scale: float
    """Size in the image over size in the trained view."""


@dataclass(frozen=True)
class ImageRecognition:
    """What recognising one uploaded image found."""

    name: str
    width: int
    height: int
    viewpoint: int
    decision: str
    """``recognized``, ``ambiguous`` or ``unknown``."""
    model: str | None
    best_model: str | None
    score: float
    threshold: float
    scores: tuple[ModelScore, ...]
    """Every model of the viewpoint, best first."""
    contenders: tuple[str, ...]
    view_id: int | None
    """The trained view that matched best."""
    outline_px: tuple[tuple[float, float], ...]
    """The matched view's outline mapped into the image (empty when nothing matched)."""
    pose: ImagePose | None
    n_features: int
    durations: Mapping[str, float] = field(default_factory=dict)
    """Seconds per stage: decode, features, retrieve, verify, decide."""

    def public(self) -> dict[str, Any]:
        """JSON form for the API and the CLI."""
        return {
            "name": self.name,
            "width": self.width,
            "height": self.height,
            "viewpoint": self.viewpoint,
            "decision": self.decision,
            "model": self.model,
            "best_model": self.best_model,
            "score": round(self.score, 5),
            "threshold": round(self.threshold, 5),
            "scores": [
                {
                    "model": s.model,
                    "score": round(s.score, 5),
                    "threshold": round(s.threshold, 5),
                    "passed": s.passed,
                }
                for s in self.scores
            ],
            "contenders": list(self.contenders),
            "view_id": self.view_id,
            "outline_px": [[round(x, 2), round(y, 2)] for x, y in self.outline_px],
            "pose": None
            if self.pose is None
            else {
                "x_px": round(self.pose.x_px, 2),
                "y_px": round(self.pose.y_px, 2),
                "angle_rad": round(self.pose.angle_rad, 5),
                "scale": round(self.pose.scale, 5),
            },
            "n_features": self.n_features,
            "durations": {k: round(v, 5) for k, v in self.durations.items()},
        }


def _pose_and_outline(
    H: NDArray[np.float64], outline: NDArray[np.float32]
) -> tuple[tuple[tuple[float, float], ...], ImagePose | None]:
    """The outline mapped by ``H`` (view -> image) and the closest similarity's parameters."""
    if len(outline) < 3 or not np.all(np.isfinite(H)) or abs(H[2, 2]) < 1e-12:
        return (), None
    mapped = cv2.perspectiveTransform(outline.reshape(-1, 1, 2).astype(np.float64), H)
    mapped = mapped.reshape(-1, 2)
    if not np.all(np.isfinite(mapped)):
        return (), None
    centre = cv2.perspectiveTransform(
        outline.astype(np.float64).mean(axis=0).reshape(1, 1, 2), H
    ).reshape(2)
    A = H[:2, :2] / H[2, 2]
    # The rotation closest to A (polar part): angle from the antisymmetric and trace parts.
    angle = math.atan2(A[1, 0] - A[0, 1], A[0, 0] + A[1, 1])
    scale = math.sqrt(abs(float(np.linalg.det(A))))
    pts = tuple((float(x), float(y)) for x, y in mapped)
    return pts, ImagePose(float(centre[0]), float(centre[1]), float(angle), scale)


def recognise_upload(
    live: LiveIndex,
    data: bytes,
    *,
    name: str,
    viewpoint: int,
    choice: ThresholdChoice,
    mask_data: bytes | None = None,
    region: Region | None = None,
    max_pixels: int = im.MAX_IMAGE_PIXELS,
    annotate: bool = False,
) -> tuple[ImageRecognition, bytes | None]:
    """Decode one uploaded image and recognise it (module docstring); CPU work for a worker
    thread.  Returns the result and, with ``annotate``, the image as JPEG with the matched
    outline drawn (what a stored inspection keeps; the decoded pixels are not kept).

    Parameters
    ----------
    live : LiveIndex
        The trained views (its lock is held while they are searched).
    data : bytes
        PNG or JPEG file; its header's size is checked before it is decoded.
    viewpoint : int
        1 (top), 2 or 3 (sides): the trained views compared with, and the thresholds.
    choice : ThresholdChoice
        The thresholds in force (:func:`backend.recognition.thresholds.current_choice`).
    mask_data : bytes, optional
        A mask file of the image's size (white = where to look).
    region : Region, optional
        A rectangle to look in (with a mask: where both say).
    """
    t0 = time.perf_counter()
    rgb = im.decode_image(data, name=name, max_pixels=max_pixels)
    mask: NDArray[np.bool_] | None = None
    if mask_data is not None:
        mask = im.decode_mask(mask_data, shape=rgb.shape[:2], name=f"mask of {name}")
    if region is not None:
        box = region.mask(rgb.shape[:2])
        mask = box if mask is None else mask & box
        if not mask.any():
            raise InvalidInput(f"{name!r}: the mask and the region do not overlap")
    t1 = time.perf_counter()
    feats = live.extract(rgb, mask)
    t2 = time.perf_counter()
    at = choice.at(viewpoint)
    with live.reading() as index:
        r = recognise(index, feats, viewpoint=viewpoint, threshold=choice)
        outline = np.zeros((0, 2), np.float32)
        if r.best is not None and r.best.H is not None:
            outline = view_outline(index.view(r.best.view_id).features)
    t3 = time.perf_counter()
    pts: tuple[tuple[float, float], ...] = ()
    pose: ImagePose | None = None
    if r.best is not None and r.best.H is not None:
        pts, pose = _pose_and_outline(np.asarray(r.best.H, dtype=np.float64), outline)
    scores = tuple(
        ModelScore(m, float(s), float(at.per_model.get(m, at.threshold)))
        for m, s in sorted(r.scores.items(), key=lambda kv: (-kv[1], kv[0]))
    )
    decide_s = max(0.0, (t3 - t2) - r.retrieval_s - r.verification_s)
    result = ImageRecognition(
        name=name,
        width=int(rgb.shape[1]),
        height=int(rgb.shape[0]),
        viewpoint=viewpoint,
        decision=r.decision,
        model=r.model,
        best_model=r.best_model,
        score=float(r.score),
        threshold=float(r.threshold),
        scores=scores,
        contenders=tuple(r.contenders),
        view_id=r.view_id,
        outline_px=pts,
        pose=pose,
        n_features=int(r.n_features),
        durations={
            "decode": t1 - t0,
            "features": t2 - t1,
            "retrieve": r.retrieval_s,
            "verify": r.verification_s,
            "decide": decide_s,
        },
    )
    return result, _annotated_jpeg(rgb, result) if annotate else None


def _annotated_jpeg(rgb: NDArray[np.uint8], result: ImageRecognition) -> bytes:
    """The image as JPEG with the matched outline drawn in green (as inspection images)."""
    img = np.ascontiguousarray(rgb.copy())
    if len(result.outline_px) >= 3:
        pts = np.round(np.asarray(result.outline_px)).astype(np.int32).reshape(-1, 1, 2)
        width = max(1, round(max(img.shape[:2]) / 200))
        cv2.polylines(img, [pts], True, (0, 220, 0), width)
    return im.encode_jpeg(img)


def _stages(durations: Mapping[str, float]) -> dict[str, float]:
    """An upload's stage times under the inspection's stage names, so reports pool them:
    decoding is its ``acquire``, retrieval and verification its ``match``."""
    d = {k: float(v) for k, v in durations.items()}
    return {
        "acquire": round(d.get("decode", 0.0), 5),
        "features": round(d.get("features", 0.0), 5),
        "match": round(d.get("retrieve", 0.0) + d.get("verify", 0.0), 5),
        "decide": round(d.get("decide", 0.0), 5),
    }


def inspection_record(
    result: ImageRecognition,
    jpeg: bytes,
    *,
    started_at: datetime,
    finished_at: datetime,
    model_ids: Mapping[str, int],
) -> InspectionRecord:
    """The inspection row of one uploaded image (source ``upload``, policy ``image``);
    ``jpeg`` is the image with the outline drawn (:func:`recognise_upload`, ``annotate``)."""
    reason = {
        "recognized": f"uploaded image {result.name!r}: {result.model} scored "
        f"{result.score:.3f} > {result.threshold:.3f}",
        "ambiguous": f"uploaded image {result.name!r}: {', '.join(result.contenders)} "
        "score within the ambiguity margin",
        "unknown": f"uploaded image {result.name!r}: no model passed its threshold (best "
        f"{result.best_model or 'none'} {result.score:.3f})",
    }[result.decision]
    scores = {s.model: round(s.score, 5) for s in result.scores}
    pose = None
    if result.pose is not None:
        pose = {
            "frame": "image",
            "image": {
                "x_px": result.pose.x_px,
                "y_px": result.pose.y_px,
                "angle_rad": result.pose.angle_rad,
                "scale": result.pose.scale,
                "outline_px": [list(p) for p in result.outline_px],
                "view_id": result.view_id,
            },
        }
    return InspectionRecord(
        started_at=started_at,
        finished_at=finished_at,
        decision=result.decision,
        reason=reason,
        policy=POLICY,
        model_id=None if result.model is None else model_ids.get(result.model),
        model_name=result.model,
        score=result.score if result.best_model is not None else None,
        viewpoints=(result.viewpoint,),
        scores=scores,
        pose=pose,
        durations=_stages(result.durations),
        views=(ViewRecord(result.viewpoint, jpeg, scores),),
        source="upload",
    )
