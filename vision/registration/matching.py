"""Descriptor matching: nearest neighbours, Lowe's ratio test and the mutual check.

Exact matching is OpenCV's brute force (L2 for real-valued descriptors, Hamming for binary
ones); approximate matching is FLANN (Muja and Lowe 2009): randomised KD-trees for real-valued
descriptors, locality-sensitive hashing for binary ones. ``method="auto"`` uses FLANN once
both sets are large enough for it to pay (:data:`FLANN_MIN_PRODUCT`).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from vision.features import Features

__all__ = [
    "FLANN_MIN_PRODUCT",
    "MATCH_METHODS",
    "Matches",
    "Neighbours",
    "check_compatible",
    "match",
    "nearest_neighbours",
]

#: ``method="auto"`` switches from brute force to FLANN when ``len(a) * len(b)`` exceeds this
#: (about 1500 x 1500 128-d features: measured crossover of OpenCV's brute force and FLANN
#: KD-trees here; below it brute force is as fast and exact).
FLANN_MIN_PRODUCT = 2_250_000
MATCH_METHODS = ("auto", "exact", "flann")

# FLANN index parameters (OpenCV's flann enums: 1 = KD-tree forest, 6 = LSH).
_FlannParams = dict[str, bool | int | float | str]
_KDTREE: _FlannParams = {"algorithm": 1, "trees": 4}
_LSH: _FlannParams = {"algorithm": 6, "table_number": 12, "key_size": 16, "multi_probe_level": 2}
_CHECKS = 64


def _frozen(a: np.ndarray) -> np.ndarray:
    a = np.ascontiguousarray(a)
    a.setflags(write=False)
    return a


@dataclass(frozen=True, eq=False)
class Neighbours:
    """The two nearest neighbours in ``b`` of every feature of ``a`` (no test applied).

    Attributes
    ----------
    index : ndarray of shape (N,), int64
        Nearest feature of ``b`` for each feature of ``a``.
    distance : ndarray of shape (N,), float64
        Its descriptor distance (L2, or Hamming bits for binary descriptors).
    second : ndarray of shape (N,), float64
        Distance to the second nearest (``inf`` when ``b`` has a single feature or the
        approximate search found only one).
    method : str
        ``"exact"`` or ``"flann"``: the search actually used.
    """

    index: np.ndarray
    distance: np.ndarray
    second: np.ndarray
    method: str

    @property
    def ratio(self) -> np.ndarray:
        """Lowe's distance ratio ``d1 / d2`` (0 where both are 0, 0 where ``d2`` is inf)."""
        with np.errstate(divide="ignore", invalid="ignore"):
            r = self.distance / self.second
        return np.nan_to_num(r, nan=0.0, posinf=1.0)


@dataclass(frozen=True, eq=False)
class Matches:
    """Tentative correspondences between features ``a`` (query) and ``b`` (train).

    Attributes
    ----------
    index_a, index_b : ndarray of shape (M,), int64
        Matched feature indices in ``a`` and in ``b``.
    distance : ndarray of shape (M,), float64
        Descriptor distance of each match.
    ratio : ndarray of shape (M,), float64
        Nearest / second-nearest distance ratio of each match (Lowe 2004, section 7.1).
    method : str
        Search used: ``"exact"`` or ``"flann"``.
    """

    index_a: np.ndarray
    index_b: np.ndarray
    distance: np.ndarray
    ratio: np.ndarray
    method: str

    def __post_init__(self) -> None:
        for name in ("index_a", "index_b"):
            object.__setattr__(self, name, _frozen(np.asarray(getattr(self, name), np.int64)))
        for name in ("distance", "ratio"):
            object.__setattr__(self, name, _frozen(np.asarray(getattr(self, name), np.float64)))

    def __len__(self) -> int:
        return len(self.index_a)

    def take(self, index: np.ndarray) -> Matches:
        """The matches selected by an integer or boolean index."""
        return Matches(
            self.index_a[index],
            self.index_b[index],
            self.distance[index],
            self.ratio[index],
            self.method,
        )


def check_compatible(a: Features, b: Features, *, allow_empty: bool = False) -> None:
    """Raise ``ValueError`` unless ``a`` and ``b`` hold comparable descriptors.

    Comparable means the same method id, descriptor version, binary flag and length; and, unless
    ``allow_empty``, at least one feature on each side.
    """
    for name, f in (("a", a), ("b", b)):
        if not isinstance(f, Features):
            raise ValueError(f"features {name} must be Features, got {type(f).__name__}")
        if not allow_empty and len(f) == 0:
            raise ValueError(f"features {name} ({f.method!r}) are empty: no keypoints to match")
    if a.method != b.method:
        raise ValueError(f"descriptor methods differ: a is {a.method!r}, b is {b.method!r}")
    if a.version != b.version:
        raise ValueError(
            f"descriptor versions of {a.method!r} differ: a is {a.version!r}, b is {b.version!r}"
        )
    if a.binary != b.binary:
        raise ValueError(f"descriptor kinds differ: a binary={a.binary}, b binary={b.binary}")
    if a.dim != b.dim:
        raise ValueError(f"descriptor lengths differ: a has {a.dim}, b has {b.dim}")


def _choose(method: str, n_a: int, n_b: int) -> str:
    if method not in MATCH_METHODS:
        raise ValueError(f"method must be one of {', '.join(MATCH_METHODS)}, got {method!r}")
    if method == "auto":
        return "flann" if n_a * n_b > FLANN_MIN_PRODUCT else "exact"
    return method


def _knn(query: np.ndarray, train: np.ndarray, binary: bool, search: str, k: int):
    matcher: cv2.DescriptorMatcher
    if search == "exact":
        matcher = cv2.BFMatcher(cv2.NORM_HAMMING if binary else cv2.NORM_L2)
    else:
        search_params: _FlannParams = {"checks": _CHECKS}
        matcher = cv2.FlannBasedMatcher(_LSH if binary else _KDTREE, search_params)
    return matcher.knnMatch(query, train, k=min(k, len(train)))


def _unpack(knn, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    index = np.full(n, -1, dtype=np.int64)
    d1 = np.full(n, np.inf)
    d2 = np.full(n, np.inf)
    for i, row in enumerate(knn):
        if len(row) >= 1:
            index[i] = row[0].trainIdx
            d1[i] = row[0].distance
        if len(row) >= 2:
            d2[i] = row[1].distance
    return index, d1, d2


def nearest_neighbours(a: Features, b: Features, *, method: str = "auto") -> Neighbours:
    """The two nearest neighbours in ``b`` of each descriptor of ``a``.

    Features of ``a`` for which an approximate (LSH) search found no neighbour at all get index
    -1 and distance ``inf``.

    Raises
    ------
    ValueError
        Empty or incompatible features (see :func:`check_compatible`), unknown method.
    """
    check_compatible(a, b)
    search = _choose(method, len(a), len(b))
    knn = _knn(a.descriptors, b.descriptors, a.binary, search, 2)
    index, d1, d2 = _unpack(knn, len(a))
    return Neighbours(_frozen(index), _frozen(d1), _frozen(d2), search)


def match(
    a: Features,
    b: Features,
    *,
    ratio: float | None = 0.8,
    mutual: bool = True,
    method: str = "auto",
) -> Matches:
    """Match descriptors of ``a`` to ``b``: nearest neighbour, ratio test, mutual check.

    Parameters
    ----------
    a, b : Features
        Query and train features of the same method, version and descriptor kind.
    ratio : float or None
        Keep a match only if ``d1 / d2 < ratio`` (Lowe 2004, section 7.1: 0.8 rejects 90 % of
        false matches and 5 % of correct ones); ``None`` keeps every nearest neighbour.
    mutual : bool
        Keep a match only if ``a[i]`` is also the nearest neighbour in ``a`` of ``b[j]``.
    method : {"auto", "exact", "flann"}
        Brute force, FLANN (KD-trees or LSH), or FLANN above :data:`FLANN_MIN_PRODUCT`.

    Returns
    -------
    Matches
        Sorted by increasing descriptor distance.

    Raises
    ------
    ValueError
        Empty or incompatible features, a ratio outside (0, 1], an unknown method.

    Examples
    --------
    >>> m = match(extract(img1, "sift"), extract(img2, "sift"))  # doctest: +SKIP
    """
    if ratio is not None and not (0.0 < float(ratio) <= 1.0):
        raise ValueError(f"ratio must be in (0, 1] or None, got {ratio!r}")
    nn = nearest_neighbours(a, b, method=method)
    keep = nn.index >= 0
    r = nn.ratio
    if ratio is not None:
        keep &= r < float(ratio)
    if mutual and keep.any():
        # Only the b features that some kept match points to need their nearest a.
        ia = np.flatnonzero(keep)
        jb = np.unique(nn.index[ia])
        back = _knn(b.descriptors[jb], a.descriptors, a.binary, nn.method, 1)
        back_index = np.full(len(b), -1, dtype=np.int64)
        back_index[jb] = _unpack(back, len(jb))[0]
        ok = back_index[nn.index[ia]] == ia
        keep[ia[~ok]] = False
    ia = np.flatnonzero(keep)
    order = np.argsort(nn.distance[ia], kind="stable")
    ia = ia[order]
    return Matches(ia, nn.index[ia], nn.distance[ia], r[ia], nn.method)
