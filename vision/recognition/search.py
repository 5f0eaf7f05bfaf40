"""Candidate retrieval: one approximate-nearest-neighbour index over the descriptors of many
trained views, and per-view voting.

Every query descriptor looks up its ``k`` nearest trained descriptors in one FLANN index
(Muja and Lowe, "Fast approximate nearest neighbors with automatic algorithm configuration",
VISAPP 2009): randomised KD-trees for real-valued descriptors, locality-sensitive hashing for
binary ones. The cost of a query grows with the logarithm of the number of stored descriptors,
not with the number of views, which is what lets the brute-force loop of the chapter's Figure
6 go.

Votes follow Lowe's database ratio test ("Distinctive image features from scale-invariant
keypoints", IJCV 2004, section 7.1), where the second distance is that of the nearest
neighbour from *another object* (neighbours from other views of the same model are not
evidence against it), generalised to models that share a feature: the models whose nearest
neighbour lies within ``d1 / ratio`` of the overall nearest ``d1`` form a tied group; each of
their neighbours closer than ``ratio`` times the nearest neighbour from outside the group
casts a vote for its view, of weight ``1 / (models in the group)``. A distinctive descriptor
(a group of one) is Lowe's test exactly; two models with identical top views split the votes
instead of losing them all, so both reach verification and the decision can say
"ambiguous". A query descriptor votes at most once per view. Views are then ranked by votes;
only the best few are verified geometrically, as many of a model's as a feature budget allows
(:mod:`vision.recognition.recognise`).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

import cv2
import numpy as np

from vision.features import Features

if TYPE_CHECKING:
    from vision.recognition.index import TrainedView

__all__ = ["DEFAULT_K", "DEFAULT_RATIO", "FOREST_SEED", "Searcher"]

#: Neighbours looked up per query descriptor (covers the neighbouring trained views of the
#: true model plus the nearest other model).
DEFAULT_K = 12
#: Lowe's ratio (2004, section 7.1: 0.8 rejects 90 % of false matches, 5 % of correct ones).
DEFAULT_RATIO = 0.8
# OpenCV flann enums: 1 = randomised KD-tree forest, 6 = LSH.
_KDTREE = {"algorithm": 1, "trees": 4}
_LSH = {"algorithm": 6, "table_number": 12, "key_size": 20, "multi_probe_level": 2}
# Leaves visited per query: 32 gave the same COIL-20 accuracy as 64 at 30 % less time
# (benchmarks/recognition.py, 180 views).
_CHECKS = 32
#: Seed of the random choices that build the forest (KD-trees' split dimensions, LSH's hash
#: functions).  OpenCV's FLANN draws them from the calling thread's ``cv::theRNG()``, whose
#: state depends on everything that thread drew before (a worker thread of a pool, an earlier
#: index): the same views gave other trees, other neighbours and other scores in another
#: process.  Seeding the thread's generator just before the build makes the forest a
#: function of the descriptors alone; the search itself draws nothing.
FOREST_SEED = 0x5EED


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
        # The build and the seeding run in one call on one thread (the generator is
        # per thread), so no other draw can come between them.
        cv2.setRNGSeed(FOREST_SEED)
        # cv2.flann_Index is missing from the OpenCV stubs.
        self._index = cv2.flann_Index(desc, _LSH if self.binary else _KDTREE)  # type: ignore[attr-defined]

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
        ndarray of shape (len(views),), float64
            Votes (a descriptor shared by a group of tied models splits its vote).
        """
        n_views = len(self.views)
        if len(query) == 0:
            return np.zeros(n_views)
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
            return np.zeros(n_views)
        idx, dist, ok, own = idx[rows], dist[rows], ok[rows], own[rows]
        mod = self.view_model[own]
        r = np.arange(len(idx))
        d1 = dist[r, np.argmax(ok, axis=1)]
        # Models tied with the nearest: their own nearest neighbour is within d1 / ratio.
        tied = ok & (dist <= d1[:, None] / ratio)
        same = mod[:, :, None] == mod[:, None, :]  # (n, k, k)
        in_group = ok & (same & tied[:, None, :]).any(axis=2)
        earlier = np.tril(np.ones((idx.shape[1], idx.shape[1]), dtype=bool), -1)
        first_of_model = ~(same & earlier[None] & ok[:, None, :]).any(axis=2)
        n_group = np.maximum((tied & first_of_model).sum(axis=1), 1)
        outside = ok & ~in_group
        # Without a neighbour from outside the group among the k, the farthest valid one
        # bounds its distance from below.
        far = np.where(ok, dist, -np.inf).max(axis=1)
        d_out = np.where(outside.any(axis=1), dist[r, np.argmax(outside, axis=1)], far)
        vote = in_group & (dist < ratio * d_out[:, None])
        rr, cc = np.nonzero(vote)
        pairs, first = np.unique(rr * n_views + own[rr, cc], return_index=True)
        weight = 1.0 / n_group[rr[first]]
        return np.bincount(pairs % n_views, weights=weight, minlength=n_views)
