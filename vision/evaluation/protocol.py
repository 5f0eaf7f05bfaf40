"""Descriptor evaluation of Mikolajczyk and Schmid ("A performance evaluation of local
descriptors", PAMI 27(10), 2005), as used in chapter section 4.2.

For an image pair with a known homography ``H`` (``a`` to ``b``):

1. keep the keypoints of the part of the scene both images show (``a`` points that ``H`` maps
   inside ``b``, ``b`` points that ``H^-1`` maps inside ``a``, optionally within a mask of
   ``a`` where ``H`` holds);
2. correspondences: region pairs with overlap error < 50 % (:mod:`.regions`). For the
   nearest-neighbour strategies, which match each region of ``a`` at most once, their number
   is the number of ``a`` regions that have at least one such partner (so that recall can
   reach 1 and never exceeds it); for ``"threshold"`` it is the number of pairs;
3. matches by a strategy with a threshold swept over all values: ``"nndr"`` (nearest neighbour
   with distance ratio ``d1/d2 < t``), ``"nn"`` (nearest neighbour with ``d1 < t``) or
   ``"threshold"`` (every pair with ``d < t``; a region may match several);
4. a match is correct when its pair overlaps with error < 50 %, and

       recall = #correct matches / #correspondences                 (chapter eq. 24)
       1 - precision = #false matches / (#correct + #false matches) (chapter eq. 25)

Summaries of a curve: ``best_recall`` (the largest recall over the sweep, Figure 14),
``recall_at(0.1)`` (the best recall with 1-precision <= 0.1) and ``auc``, the area under the
upper envelope ``R(x) = max{recall : 1-precision <= x}`` over ``x`` in [0, 1].
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from vision.evaluation.regions import Overlaps, apply_homography, overlap_errors
from vision.features import Features
from vision.registration import check_compatible, nearest_neighbours

__all__ = [
    "STRATEGIES",
    "PairEvaluation",
    "RecallCurve",
    "common_part",
    "correspondences",
    "curve_from_matches",
    "evaluate_pair",
]

STRATEGIES = ("nndr", "nn", "threshold")
_ENVELOPE = np.linspace(0.0, 1.0, 1001)


@dataclass(frozen=True, eq=False)
class RecallCurve:
    """Recall versus 1-precision over a swept matching threshold.

    Attributes
    ----------
    threshold : ndarray of shape (T,)
        Threshold values, increasing (each keeps the matches with score <= it).
    recall : ndarray of shape (T,)
        Equation 24 at each threshold.
    one_minus_precision : ndarray of shape (T,)
        Equation 25 at each threshold.
    n_correspondences : int
        Denominator of the recall.
    """

    threshold: np.ndarray
    recall: np.ndarray
    one_minus_precision: np.ndarray
    n_correspondences: int

    def envelope(self, x: np.ndarray) -> np.ndarray:
        """``R(x)``: the best recall with 1-precision <= ``x`` (0 where none)."""
        x = np.asarray(x, dtype=np.float64)
        if len(self.recall) == 0:
            return np.zeros_like(x)
        order = np.argsort(self.one_minus_precision, kind="stable")
        fp = self.one_minus_precision[order]
        best = np.maximum.accumulate(self.recall[order])
        k = np.searchsorted(fp, x, side="right")
        return np.where(k > 0, best[np.maximum(k - 1, 0)], 0.0)

    def recall_at(self, one_minus_precision: float) -> float:
        """Best recall reachable with 1-precision at most the given value."""
        return float(self.envelope(np.array([one_minus_precision]))[0])

    @property
    def best_recall(self) -> float:
        """Largest recall over the sweep (Figure 14's "best recall")."""
        return float(self.recall.max()) if len(self.recall) else 0.0

    @property
    def auc(self) -> float:
        """Area under ``R(x)`` for ``x`` in [0, 1] (trapezoids on a 0.001 grid), in [0, 1]."""
        return float(np.trapezoid(self.envelope(_ENVELOPE), _ENVELOPE))


@dataclass(frozen=True, eq=False)
class PairEvaluation:
    """Evaluation of one image pair with one descriptor.

    Attributes
    ----------
    curve : RecallCurve
    n_a, n_b : int
        Keypoints in the common part of the scene.
    n_correspondences : int
        Ground-truth correspondences (see :func:`correspondences`).
    strategy : str
        Matching strategy swept.
    """

    curve: RecallCurve
    n_a: int
    n_b: int
    n_correspondences: int
    strategy: str

    @property
    def recall_at_01(self) -> float:
        """Recall at 1-precision = 0.1."""
        return self.curve.recall_at(0.1)

    @property
    def best_recall(self) -> float:
        return self.curve.best_recall

    @property
    def auc(self) -> float:
        return self.curve.auc


def _inside(xy: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    h, w = shape
    return (xy[:, 0] >= 0) & (xy[:, 0] <= w - 1) & (xy[:, 1] >= 0) & (xy[:, 1] <= h - 1)


def _in_mask(xy: np.ndarray, mask: np.ndarray) -> np.ndarray:
    h, w = mask.shape
    c = np.clip(np.rint(xy[:, 0]).astype(int), 0, w - 1)
    r = np.clip(np.rint(xy[:, 1]).astype(int), 0, h - 1)
    return _inside(xy, (h, w)) & (mask[r, c] > 0)


def common_part(
    a: Features, b: Features, H: np.ndarray, mask_a: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Indices of the keypoints of ``a`` and ``b`` that both images see (see module docstring)."""
    pa = apply_homography(H, a.keypoints.xy)
    pb = apply_homography(np.linalg.inv(H), b.keypoints.xy)
    keep_a = _inside(pa, b.image_shape)
    keep_b = _inside(pb, a.image_shape)
    if mask_a is not None:
        keep_a &= _in_mask(a.keypoints.xy, mask_a)
        keep_b &= _in_mask(pb, mask_a)
    return np.flatnonzero(keep_a), np.flatnonzero(keep_b)


def correspondences(overlaps: Overlaps, strategy: str = "nndr") -> int:
    """Number of ground-truth correspondences for a strategy (eq. 24's denominator).

    ``"threshold"`` may match a region several times: every overlapping pair counts. The
    nearest-neighbour strategies match each ``a`` region once: the count is the number of ``a``
    regions that have an overlapping partner.
    """
    if strategy == "threshold":
        return len(overlaps.index_a)
    return len(np.unique(overlaps.index_a))


def curve_from_matches(
    score: np.ndarray, correct: np.ndarray, n_correspondences: int
) -> RecallCurve:
    """Recall / 1-precision as the threshold on ``score`` sweeps every value.

    Parameters
    ----------
    score : ndarray of shape (M,)
        Matching score of each candidate match (lower is better: distance or ratio).
    correct : ndarray of shape (M,), bool
        Whether each match is correct under the ground truth.
    n_correspondences : int
        Number of ground-truth correspondences (eq. 24's denominator).
    """
    score = np.asarray(score, dtype=np.float64).reshape(-1)
    correct = np.asarray(correct, dtype=bool).reshape(-1)
    if score.shape != correct.shape:
        raise ValueError(f"score and correct differ in length: {score.shape} vs {correct.shape}")
    if n_correspondences < 0:
        raise ValueError(f"n_correspondences must be >= 0, got {n_correspondences!r}")
    order = np.argsort(score, kind="stable")
    s, c = score[order], correct[order]
    # One point per distinct threshold: the last index of each run of equal scores.
    last = np.r_[np.flatnonzero(np.diff(s) > 0), len(s) - 1] if len(s) else np.zeros(0, int)
    tp = np.cumsum(c)[last]
    fp = np.cumsum(~c)[last]
    recall = tp / n_correspondences if n_correspondences else np.zeros(len(last))
    omp = fp / np.maximum(tp + fp, 1)
    return RecallCurve(
        s[last], recall.astype(np.float64), omp.astype(np.float64), n_correspondences
    )


def _distance_matrix(a: np.ndarray, b: np.ndarray, binary: bool) -> np.ndarray:
    if binary:
        pa = np.unpackbits(a, axis=1).astype(np.float32)
        pb = np.unpackbits(b, axis=1).astype(np.float32)
        return pa @ (1.0 - pb).T + (1.0 - pa) @ pb.T
    a64, b64 = a.astype(np.float64), b.astype(np.float64)
    d2 = (a64**2).sum(1)[:, None] + (b64**2).sum(1)[None, :] - 2.0 * a64 @ b64.T
    return np.sqrt(np.maximum(d2, 0.0))


def evaluate_pair(
    a: Features,
    b: Features,
    H: np.ndarray,
    *,
    strategy: str = "nndr",
    mask_a: np.ndarray | None = None,
    max_error: float = 0.5,
    region_scale: float = 1.0,
    normalise_px: float | None = 30.0,
) -> PairEvaluation:
    """Recall versus 1-precision of descriptors ``a``/``b`` under the ground truth ``H``.

    Parameters
    ----------
    a, b : Features
        Features of the two images (same method, version and kind).
    H : ndarray of shape (3, 3)
        True homography mapping pixels of ``a`` to ``b``.
    strategy : {"nndr", "nn", "threshold"}
        Matching strategy whose threshold is swept (module docstring).
    mask_a : ndarray of shape a.image_shape, optional
        Where in ``a`` the homography holds (e.g. a planar face); keypoints elsewhere are ignored.
    max_error : float
        Overlap error below which two regions correspond (0.5).
    region_scale, normalise_px
        Region enlargement and optional size normalisation of the overlap error (see
        :mod:`vision.evaluation.regions`).

    Raises
    ------
    ValueError
        Incompatible features, unknown strategy, bad ``H`` or mask.
    """
    if strategy not in STRATEGIES:
        raise ValueError(f"strategy must be one of {', '.join(STRATEGIES)}, got {strategy!r}")
    check_compatible(a, b, allow_empty=True)
    H = np.asarray(H, dtype=np.float64)
    if H.shape != (3, 3) or not np.all(np.isfinite(H)) or abs(np.linalg.det(H)) < 1e-12:
        raise ValueError(f"H must be a finite invertible 3x3 matrix, got {H.tolist()}")
    if mask_a is not None and np.shape(mask_a) != tuple(a.image_shape):
        raise ValueError(f"mask_a must have shape {a.image_shape}, got {np.shape(mask_a)}")
    ka, kb = common_part(a, b, H, mask_a)
    fa, fb = a.take(ka), b.take(kb)
    ov = overlap_errors(
        fa.keypoints,
        fb.keypoints,
        H,
        max_error=max_error,
        region_scale=region_scale,
        normalise_px=normalise_px,
    )
    n_corr = correspondences(ov, strategy)
    empty = RecallCurve(np.zeros(0), np.zeros(0), np.zeros(0), n_corr)
    if len(fa) == 0 or len(fb) == 0:
        return PairEvaluation(empty, len(fa), len(fb), n_corr, strategy)
    # Pairs (i, j) are compared through the flat index i * len(fb) + j.
    good_keys = ov.index_a.astype(np.int64) * len(fb) + ov.index_b
    if strategy == "threshold":
        D = _distance_matrix(fa.descriptors, fb.descriptors, fa.binary)
        key = np.arange(D.size, dtype=np.int64)  # every pair, in D's row-major order
        score = D.reshape(-1)
    else:
        nn = nearest_neighbours(fa, fb, method="exact")
        ia = np.flatnonzero(nn.index >= 0)
        key = ia.astype(np.int64) * len(fb) + nn.index[ia]
        score = (nn.ratio if strategy == "nndr" else nn.distance)[ia]
    correct = np.isin(key, good_keys)
    curve = curve_from_matches(score, correct, n_corr)
    return PairEvaluation(curve, len(fa), len(fb), n_corr, strategy)
