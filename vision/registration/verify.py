"""Geometric verification of tentative matches: a homography or an affine map fitted robustly.

MAGSAC++ (Barath et al., CVPR 2020, OpenCV's ``USAC_MAGSAC``) is the default estimator; classic
RANSAC (Fischler and Bolles 1981) is available for comparison. Models map points of image ``a``
to image ``b``: ``x_b ~ H @ x_a`` (Hartley and Zisserman 2003, section 4.7).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from vision.features import Features
from vision.registration.matching import Matches

__all__ = ["MODELS", "ROBUST_METHODS", "Verification", "verify"]

MODELS = ("homography", "affine")
#: Robust estimators by name -> OpenCV flag.
ROBUST_METHODS = {"usac_magsac": cv2.USAC_MAGSAC, "ransac": cv2.RANSAC}
_MIN_SAMPLE = {"homography": 4, "affine": 3}


@dataclass(frozen=True, eq=False)
class Verification:
    """The geometric model found among the matches, and which matches agree with it.

    Attributes
    ----------
    model : str
        ``"homography"`` or ``"affine"``.
    H : ndarray of shape (3, 3) or None
        The model as a 3x3 matrix mapping homogeneous pixels of ``a`` to ``b`` (affine: last
        row ``0 0 1``); ``None`` when no model was found (too few matches, degenerate fit).
    inliers : ndarray of shape (M,), bool
        Per match: reprojection error below ``reproj_px`` under ``H`` (all False without one).
    reproj_px : float
        Inlier threshold used, pixels.
    min_sample : int
        Minimal sample size of the model (4 for a homography, 3 for an affine map).
    """

    model: str
    H: np.ndarray | None
    inliers: np.ndarray
    reproj_px: float
    min_sample: int

    @property
    def found(self) -> bool:
        """True when a non-degenerate model was fitted."""
        return self.H is not None

    @property
    def n_inliers(self) -> int:
        """Number of matches consistent with the model."""
        return int(np.count_nonzero(self.inliers))


def _degenerate(H: np.ndarray) -> bool:
    """Reject fits that fold or collapse the image: a flipped or near-singular linear part, or
    a projective row so strong that the horizon crosses the working area."""
    if not np.all(np.isfinite(H)) or abs(H[2, 2]) < 1e-12:
        return True
    H = H / H[2, 2]
    det = float(np.linalg.det(H[:2, :2]))
    return det <= 1e-4 or det >= 1e4 or float(np.abs(H[2, :2]).max()) > 0.01


def verify(
    matches: Matches,
    a: Features,
    b: Features,
    *,
    model: str = "homography",
    method: str = "usac_magsac",
    reproj_px: float = 3.0,
    max_iters: int = 2000,
    confidence: float = 0.999,
) -> Verification:
    """Fit a homography or an affine map robustly to the matched keypoints.

    Parameters
    ----------
    matches : Matches
        From :func:`vision.registration.match` between ``a`` and ``b``.
    a, b : Features
        The features the matches index into.
    model : {"homography", "affine"}
        Homography for planar scenes or pure camera rotation; affine (6 dof) for small views.
    method : {"usac_magsac", "ransac"}
        Robust estimator.
    reproj_px : float
        Inlier threshold on the reprojection error in ``b``, pixels (> 0).
    max_iters : int
        Iteration cap of the robust loop.
    confidence : float
        Stop when a better model is this unlikely, in (0, 1).

    Returns
    -------
    Verification
        ``H`` is ``None`` with fewer matches than the minimal sample, or a degenerate fit.

    Raises
    ------
    ValueError
        Unknown model or method, non-positive threshold, matches that index outside ``a``/``b``.
    """
    if model not in MODELS:
        raise ValueError(f"model must be one of {', '.join(MODELS)}, got {model!r}")
    if method not in ROBUST_METHODS:
        raise ValueError(f"method must be one of {', '.join(ROBUST_METHODS)}, got {method!r}")
    if not (np.isfinite(reproj_px) and reproj_px > 0):
        raise ValueError(f"reproj_px must be a positive number of pixels, got {reproj_px!r}")
    if not 0.0 < confidence < 1.0:
        raise ValueError(f"confidence must be in (0, 1), got {confidence!r}")
    m = len(matches)
    if m and (matches.index_a.max() >= len(a) or matches.index_b.max() >= len(b)):
        raise ValueError(
            f"matches index features beyond a ({len(a)}) or b ({len(b)}): wrong feature sets?"
        )
    need = _MIN_SAMPLE[model]
    none = Verification(model, None, np.zeros(m, dtype=bool), float(reproj_px), need)
    if m < need:
        return none
    src = a.keypoints.xy[matches.index_a].astype(np.float32)
    dst = b.keypoints.xy[matches.index_b].astype(np.float32)
    flag = ROBUST_METHODS[method]
    if model == "homography":
        H, mask = cv2.findHomography(
            src, dst, flag, float(reproj_px), maxIters=int(max_iters), confidence=confidence
        )
    else:
        A, mask = cv2.estimateAffine2D(
            src,
            dst,
            method=flag,
            ransacReprojThreshold=float(reproj_px),
            maxIters=int(max_iters),
            confidence=confidence,
        )
        H = None if A is None else np.vstack([A, [0.0, 0.0, 1.0]])
    if H is None or mask is None or _degenerate(H):
        return none
    H = H / H[2, 2]
    inliers = np.asarray(mask).reshape(-1).astype(bool)
    if inliers.sum() < need:
        return none
    H.setflags(write=False)
    inliers.setflags(write=False)
    return Verification(model, H, inliers, float(reproj_px), need)
