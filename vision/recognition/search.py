"""Candidate retrieval: one approximate-nearest-neighbour index over the descriptors of many
trained views, and per-view voting.

Every query descriptor looks up its ``k`` nearest trained descriptors in one FLANN index
(Muja and Lowe, "Fast approximate nearest neighbors with automatic algorithm configuration",
VISAPP 2009): randomised KD-trees for real-valued descriptors, locality-sensitive hashing for
binary ones. The cost of a query grows with the logarithm of the number of stored descriptors,
not with the number of views, which is what lets the brute-force loop of the chapter's Figure
6 go.

Votes follow Lowe's database ratio test ("Distinctive image features from scale-invariant
keypoints", IJCV 2004, section 7.1): the nearest neighbour belongs to model ``m``; the second
distance is that of the nearest neighbour from *another* model (neighbours from other views
of the same model are not evidence against it). Each neighbour of model ``m`` closer than
``ratio`` times that distance casts one vote for its view; a query descriptor votes at most
once per view. Views are then ranked by votes; only the best few are verified
geometrically (:mod:`vision.recognition.recognise`).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

import cv2
import numpy as np

from vision.features import Features

if TYPE_CHECKING:
    from vision.recognition.index import TrainedView

__all__ = ["DEFAULT_K", "DEFAULT_RATIO", "Searcher"]

#: Neighbours looked up per query descriptor (covers the neighbouring trained views of the
#: true model plus the nearest other model).
DEFAULT_K = 12
#: Lowe's ratio (2004, section 7.1: 0.8 rejects 90 % of false matches, 5 % of correct ones).
DEFAULT_RATIO = 0.8
# OpenCV flann enums: 1 = randomised KD-tree forest, 6 = LSH.
_KDTREE = {"algorithm": 1, "trees": 4}
_LSH = {"algorithm": 6, "table_number": 12, "key_size": 20, "multi_probe_level": 2}
_CHECKS = 64


class Searcher:
    """ANN index over the descriptors of a fixed list of trained views.

    Parameters
    ----------
    views : sequence of TrainedView
        Views of one method and descriptor version (the index guarantees it).
    """

    def __init__(self, views: Sequence[TrainedView]) -> None:
        if not views:
            raise ValueError("a searcher needs at least one view")
        self.views = tuple(views)
        self.models = tuple(sorted({v.model for v in views}))
        code = {m: i for i, m in enumerate(self.models)}
        self.view_model = np.array([code[v.model] for v in views], dtype=np.int64)
        counts = [len(v.features) for v in views]
        self.owner = np.repeat(np.arange(len(views)), counts)
        first = views[0].features
        self.binary = first.binary
        desc = np.ascontiguousarray(np.concatenate([v.features.descriptors for v in views]))
        self.n_descriptors = len(desc)
        self._index = cv2.flann_Index(desc, _LSH if self.binary else _KDTREE)

    def position(self, view_id: int) -> int:
        """Position of a view id in :attr:`views` (``-1`` if it is not there)."""
        for i, v in enumerate(self.views):
            if v.view_id == view_id:
                return i
        return -1

    def votes(
        self,
        query: Features,
        *,
        k: int = DEFAULT_K,
        ratio: float = DEFAULT_RATIO,
        models: Sequence[str] | None = None,
        exclude_view: int | None = None,
    ) -> np.ndarray:
        """Votes per view (aligned with :attr:`views`) for the query's descriptors.

        Parameters
        ----------
        query : Features
            Query features, comparable with the trained ones.
        k : int
            Neighbours per descriptor.
        ratio : float
            Lowe's database ratio (module docstring), in (0, 1].
        models : sequence of str, optional
            Only these models may receive votes (the others' neighbours are ignored).
        exclude_view : int, optional
            View id whose descriptors are ignored (leave-one-view-out).

        Returns
        -------
        ndarray of shape (len(views),), int64
        """
        n_views = len(self.views)
        if len(query) == 0:
            return np.zeros(n_views, dtype=np.int64)
        allowed = np.ones(n_views, dtype=bool)
        if models is not None:
            allowed = np.isin(np.array(self.models)[self.view_model], list(models))
        if exclude_view is not None:
            pos = self.position(exclude_view)
            if pos >= 0:
                allowed[pos] = False
        k = int(min(k + (8 if exclude_view is not None else 0), self.n_descriptors))
        q = np.ascontiguousarray(query.descriptors)
        idx, dist = self._index.knnSearch(q, k, params={"checks": _CHECKS})
        idx = np.asarray(idx, dtype=np.int64).reshape(len(q), -1)
        dist = np.asarray(dist, dtype=np.float64).reshape(len(q), -1)
        if not self.binary:
            dist = np.sqrt(np.maximum(dist, 0.0))  # FLANN's L2 is squared
        ok = (idx >= 0) & (idx < self.n_descriptors)
        own = self.owner[np.where(ok, idx, 0)]
        ok &= allowed[own]
        rows = ok.any(axis=1)
        if not rows.any():
            return np.zeros(n_views, dtype=np.int64)
        idx, dist, ok, own = idx[rows], dist[rows], ok[rows], own[rows]
        mod = self.view_model[own]
        r = np.arange(len(idx))
        m1 = mod[r, np.argmax(ok, axis=1)]
        other = ok & (mod != m1[:, None])
        has_other = other.any(axis=1)
        # Without a neighbour from another model among the k, the farthest valid one bounds it.
        far = np.where(ok, dist, -np.inf).max(axis=1)
        d_other = np.where(has_other, dist[r, np.argmax(other, axis=1)], far)
        vote = ok & (mod == m1[:, None]) & (dist < ratio * d_other[:, None])
        rr, cc = np.nonzero(vote)
        pairs = np.unique(rr * n_views + own[rr, cc])
        return np.bincount(pairs % n_views, minlength=n_views).astype(np.int64)
