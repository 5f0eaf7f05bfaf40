"""Feature-based registration of two images (chapter section 3.3.1) and its score in [0, 1].

The score is what recognition thresholds, as the chapter thresholds VisionPro's score
(section 3.5): it must be near 1 for two views of the same planar object and near 0 for
unrelated images. It is defined as

    score = saturation * sqrt(inlier_ratio * coverage)

with, for ``n`` inliers of the verified model among ``m`` tentative matches:

* ``saturation = 1 - exp(-(n - k) / N_SAT)`` for ``n > k`` (else 0), ``k`` the minimal sample
  of the model (4 for a homography: any 4 matches fit one exactly, so they prove nothing) and
  ``N_SAT = 20`` (20 supporting inliers give 0.63, 60 give 0.95);
* ``inlier_ratio = n / m``: the share of tentative matches that the model explains;
* ``coverage = area(hull(inliers in a)) / area(hull(all keypoints of a))``, clipped to [0, 1]:
  how much of the first image's feature-bearing area the agreement spans, so that a handful
  of inliers clustered on one small patch (a logo, a repeated texture) scores low.

No verified model (fewer matches than the minimal sample, or a degenerate fit) scores 0.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from vision.features import Features, extract
from vision.registration.matching import Matches, match
from vision.registration.verify import Verification, verify

__all__ = ["N_SAT", "Registration", "register", "registration_score"]

#: Inlier count (beyond the minimal sample) at which the saturation term reaches 1 - 1/e.
N_SAT = 20.0


@dataclass(frozen=True, eq=False)
class Registration:
    """Result of :func:`register`.

    Attributes
    ----------
    a, b : Features
        The features of the two images.
    matches : Matches
        Tentative matches (ratio test, mutual check).
    verification : Verification
        Robust model fit and its inlier mask over ``matches``.
    score : float
        Registration score in [0, 1] (module docstring).
    saturation, inlier_ratio, coverage : float
        The three terms of the score, each in [0, 1].
    """

    a: Features
    b: Features
    matches: Matches
    verification: Verification
    score: float
    saturation: float
    inlier_ratio: float
    coverage: float

    @property
    def H(self) -> np.ndarray | None:
        """Model mapping pixels of ``a`` to ``b`` (``None`` when registration failed)."""
        return self.verification.H

    @property
    def n_inliers(self) -> int:
        """Matches consistent with the model."""
        return self.verification.n_inliers


def _hull_area(xy: np.ndarray) -> float:
    if len(xy) < 3:
        return 0.0
    hull = cv2.convexHull(np.ascontiguousarray(xy, dtype=np.float32))
    return float(cv2.contourArea(hull))


def registration_score(
    verification: Verification, matches: Matches, a: Features
) -> tuple[float, float, float, float]:
    """Score of a verified registration: ``(score, saturation, inlier_ratio, coverage)``.

    See the module docstring for the definition; every value is in [0, 1].
    """
    n = verification.n_inliers
    m = len(matches)
    if not verification.found or m == 0:
        return 0.0, 0.0, 0.0, 0.0
    k = verification.min_sample
    saturation = 1.0 - math.exp(-(n - k) / N_SAT) if n > k else 0.0
    ratio = n / m
    all_area = _hull_area(a.keypoints.xy)
    inl = a.keypoints.xy[matches.index_a[verification.inliers]]
    coverage = min(1.0, _hull_area(inl) / all_area) if all_area > 0 else 0.0
    score = saturation * math.sqrt(ratio * coverage)
    return float(score), float(saturation), float(ratio), float(coverage)


def _features(x: np.ndarray | Features, name: str, method: str, options: dict) -> Features:
    if isinstance(x, Features):
        return x
    if isinstance(x, np.ndarray):
        return extract(x, method, **options)
    raise ValueError(f"{name} must be an image array or Features, got {type(x).__name__}")


def register(
    a: np.ndarray | Features,
    b: np.ndarray | Features,
    *,
    method: str = "sift",
    ratio: float | None = 0.8,
    mutual: bool = True,
    match_method: str = "auto",
    model: str = "homography",
    robust: str = "usac_magsac",
    reproj_px: float = 3.0,
    **extract_options,
) -> Registration:
    """Register image (or features) ``a`` onto ``b``: extract, match, verify, score.

    Parameters
    ----------
    a, b : ndarray (H, W[, 3]) uint8 or Features
        Images (features are extracted with ``method``) or features already extracted.
    method : str
        Feature method for images (ignored for Features), see :func:`vision.features.extract`.
    ratio, mutual, match_method
        Passed to :func:`vision.registration.match` (``match_method`` is its ``method``).
    model, robust, reproj_px
        Passed to :func:`vision.registration.verify` (``robust`` is its ``method``).
    **extract_options
        Options for :func:`vision.features.extract`.

    Returns
    -------
    Registration
        With ``score`` in [0, 1] and ``H`` mapping pixels of ``a`` to ``b``.

    Raises
    ------
    ValueError
        No features in either image, features of different methods, versions or kinds, or bad
        parameters of the steps.
    """
    fa = _features(a, "a", method, extract_options)
    fb = _features(b, "b", method, extract_options)
    matches = match(fa, fb, ratio=ratio, mutual=mutual, method=match_method)
    ver = verify(matches, fa, fb, model=model, method=robust, reproj_px=reproj_px)
    score, sat, inl, cov = registration_score(ver, matches, fa)
    return Registration(fa, fb, matches, ver, score, sat, inl, cov)
