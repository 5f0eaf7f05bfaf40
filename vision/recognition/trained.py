"""A trained view of the recognition index and the viewpoint numbers (chapter section 3.5.3:
viewpoint 1 is the top view, 2 and 3 the side positions).

Shared by the index and its byte form (:mod:`vision.recognition.serial`), so that neither
imports the other.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal, overload

import numpy as np

from vision.features import Features

__all__ = ["VIEWPOINTS", "TrainedView", "check_viewpoint"]

VIEWPOINTS = (1, 2, 3)


@dataclass(frozen=True, eq=False)
class TrainedView:
    """One trained image of a model, kept as its features.

    Attributes
    ----------
    view_id : int
        Stable id (unique in the index, kept through serialisation).
    model : str
        Model name (one physical part on one sitting base).
    viewpoint : int
        1 (top), 2 or 3 (side positions).
    part, base : str or None
        Physical part and sitting base the model stands for (section 3.5.3), if given.
    features : Features
        Keypoints (pixels of the trained image) and descriptors, extracted inside the mask.
    colour : ndarray of shape (SIGNATURE_SIZE,) or None
        Colour signature of the view's region (:mod:`vision.recognition.colour`), ``None``
        when the view was trained from grey pixels or from features alone.
    outline : ndarray of shape (K, 2) or None
        Convex outline of the region ``colour`` describes (pixels of the trained image);
        mapped into a query by a verified ``H`` to describe the same region there.
    """

    view_id: int
    model: str
    viewpoint: int
    part: str | None
    base: str | None
    features: Features
    colour: np.ndarray | None = None
    outline: np.ndarray | None = None


@overload
def check_viewpoint(viewpoint: object, *, allow_none: Literal[False] = False) -> int: ...
@overload
def check_viewpoint(viewpoint: object, *, allow_none: bool) -> int | None: ...
def check_viewpoint(viewpoint: object, *, allow_none: bool = False) -> int | None:
    """Validate a viewpoint number (1, 2 or 3; ``None`` = every viewpoint where allowed)."""
    if viewpoint is None and allow_none:
        return None
    if isinstance(viewpoint, bool) or not isinstance(viewpoint, int | np.integer):
        raise ValueError(f"viewpoint must be one of {VIEWPOINTS}, got {viewpoint!r}")
    if int(viewpoint) not in VIEWPOINTS:
        raise ValueError(f"viewpoint must be one of {VIEWPOINTS}, got {viewpoint!r}")
    return int(viewpoint)
