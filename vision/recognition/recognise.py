"""Scores and the 2D decision (chapter section 3.5.1): which trained model an image shows.

Pipeline of :func:`recognise`: features of the query (inside the object mask) -> votes of an
approximate-nearest-neighbour search over every trained view of the viewpoint
(:mod:`vision.recognition.search`) -> geometric verification of the best-voted views only
(``max_models`` models, ``views_per_model`` views each, and more of a model's views while
their features fit its budget, :data:`VERIFY_FEATURES`) -> a score per model -> the decision.

Score of a model
    The registration score of its best verified view, as defined in
    :mod:`vision.registration.register`:

        score = saturation * sqrt(inlier_ratio * coverage)            (in [0, 1])

    with the trained view as image ``a`` and the query as image ``b``, so that
    ``saturation = 1 - exp(-(n - k) / 20)`` counts the ``n`` inliers beyond the minimal sample
    ``k``, ``inlier_ratio`` is the share of tentative matches the fitted model explains and
    ``coverage`` is the share of the trained view's feature area that the inliers span (how
    much of the model was found, as Cognex PatMax's "coverage"). Models that were not
    verified score 0. The chapter asks for exactly this kind of number: "a score for each
    model to indicate how close each model matches with the object, with 1.0 being the
    highest and 0.0 being the lowest" (section 3.5.1).

Clutter (reported, not scored)
    ``1 - inliers / (query keypoints inside the trained view's outline mapped by H)``: the
    share of the object region's features that the model does not explain (PatMax's
    "clutter"); high clutter with a good score means extra or occluding material.

Decision (section 3.5.1, with an ambiguity rule the chapter lacks)
    ``recognized`` when the best model's score exceeds its threshold (per model, else
    global) and the runner-up scores below ``(1 - margin)`` times the best;
    ``ambiguous`` when the runner-up is within that margin (the chapter's "more than one
    model getting a score bigger than the threshold" resolved by asking for another view
    instead of guessing); ``unknown`` when no model passes (the chapter's "report an error").
"""

from __future__ import annotations

import math
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from types import MappingProxyType

import cv2
import numpy as np

from vision.features import Features
from vision.recognition.choice import ThresholdChoice
from vision.recognition.index import ViewIndex, check_viewpoint
from vision.recognition.search import DEFAULT_K, DEFAULT_RATIO
from vision.registration import match, registration_score, verify

__all__ = [
    "DECISIONS",
    "DEFAULT_MARGIN",
    "DEFAULT_THRESHOLD",
    "SIDE_VIEWPOINTS",
    "Candidate",
    "Recognition",
    "decide",
    "decide_with",
    "recognise",
    "resolve_threshold",
    "search_of",
]

DECISIONS = ("recognized", "ambiguous", "unknown")
#: Global threshold used when none is given. It is a fallback only: run
#: :func:`vision.recognition.choose_threshold` on the trained views of the cell.
DEFAULT_THRESHOLD = 0.1
#: Relative confusion margin: ambiguous when runner-up >= (1 - margin) * best.
DEFAULT_MARGIN = 0.2
#: Inlier threshold of the verification, pixels (MAGSAC++ marginalises the noise scale below
#: it, so the value is not critical; Barath et al. 2020).
REPROJ_PX = 3.0
#: Side viewpoints, searched together: with the arm's two side azimuths (inner and outer,
#: section 4.1), the inner view of an object turned by 180 degrees is its outer view, so a
#: side query at any object yaw finds twice the taught yaws to compare with.
SIDE_VIEWPOINTS = (2, 3)


def search_of(viewpoint: int) -> tuple[int, ...]:
    """Trained viewpoints a query of ``viewpoint`` is compared with (sides pooled)."""
    return SIDE_VIEWPOINTS if viewpoint in SIDE_VIEWPOINTS else (viewpoint,)


#: Views reach verification only with at least this many votes, and at least this share of
#: the best view's votes (fewer than 2 agreeing descriptors cannot fix an affine map).
MIN_VOTES = 2.0
REL_VOTES = 0.2
#: Verification budget per model beyond its ``views_per_model`` best-voted views, in trained
#: features: more of its voted views are verified, in order of votes, while the features of
#: the views verified for it stay within ``views_per_model`` times this (and at most
#: :data:`MAX_VIEWS_VERIFIED` views).  The cost of verifying a view grows with its features
#: (exact matching against the query, then the fit), so this is the budget of two views of a
#: richly textured part (1,000 features each) spent on as many views of a plain one as fit.
#: Votes rank the views of a plain part poorly: its taught top views show the same surface
#: at other yaws, and with 55-75 features each they draw 8-21 votes with little between
#: them, while their registration scores spread from 0.05 to 0.53.  Two views by votes
#: missed the one that registers: the valve block's top view scored 0.00-0.12 against
#: 0.27-0.42 from its best view, and was reported unknown (``benchmarks.inspection``, constant
#: belt speed; ``benchmarks.recognition_budget`` measures it).
VERIFY_FEATURES = 1_000
MAX_VIEWS_VERIFIED = 32


@dataclass(frozen=True, eq=False)
class Candidate:
    """One model's best verified view and the parts of its score.

    Attributes
    ----------
    model : str
    view_id : int
        The trained view that scored best for this model.
    viewpoint : int
        Viewpoint of that trained view.
    score : float
        Registration score in [0, 1] (module docstring).
    saturation, inlier_ratio, coverage : float
        The three factors of the score, each in [0, 1].
    clutter : float
        Share of query keypoints inside the mapped model outline that are not inliers, [0, 1].
    n_inliers, n_matches : int
        Inliers of the verified model and tentative matches.
    votes : float
        ANN votes the view received (:class:`vision.recognition.search.Searcher`).
    H : ndarray of shape (3, 3) or None
        Map from pixels of the trained view to pixels of the query (``x_q ~ H @ x_view``);
        ``None`` when verification found no model.
    inlier_xy : ndarray of shape (n_inliers, 4) or None
        The inlier correspondences behind ``H``: trained-view ``x, y`` then query ``x, y``,
        pixels.  The pose (:mod:`vision.pose`) fits the object's motion to them
        with each feature's own height: ``H`` is one plane's map, and the features of a
        wheel or a bracket lie at several heights seen from cameras tens of millimetres
        apart.
    """

    model: str
    view_id: int
    viewpoint: int
    score: float
    saturation: float
    inlier_ratio: float
    coverage: float
    clutter: float
    n_inliers: int
    n_matches: int
    votes: float
    H: np.ndarray | None
    inlier_xy: np.ndarray | None = None


@dataclass(frozen=True, eq=False)
class Recognition:
    """Result of :func:`recognise`.

    Attributes
    ----------
    decision : {"recognized", "ambiguous", "unknown"}
    model : str or None
        The recognised model (``None`` unless ``decision == "recognized"``).
    best_model : str or None
        Highest-scoring model whatever the decision (``None`` if nothing was verified).
    score : float
        Score of ``best_model`` (0 if none), in [0, 1].
    scores : mapping of str to float
        Score of every model searched (0 for models that were not verified).
    contenders : tuple of str
        Models passing their threshold within the margin of the best (several when ambiguous).
    candidates : tuple of Candidate
        Verified models, best first, with the parts of their scores.
    threshold : float
        Threshold applied to ``best_model``.
    margin : float
        Relative confusion margin used.
    viewpoint : int or None
        Viewpoint whose trained views were searched (``None`` = all).
    n_features : int
        Query features.
    retrieval_s, verification_s : float
        Time of the ANN search and voting, and of the geometric verification, seconds.
    """

    decision: str
    model: str | None
    best_model: str | None
    score: float
    scores: Mapping[str, float]
    contenders: tuple[str, ...]
    candidates: tuple[Candidate, ...]
    threshold: float
    margin: float
    viewpoint: int | None
    n_features: int
    retrieval_s: float
    verification_s: float

    @property
    def best(self) -> Candidate | None:
        """The best candidate (``None`` if nothing was verified)."""
        return self.candidates[0] if self.candidates else None

    @property
    def view_id(self) -> int | None:
        """Trained view id of the best verified view."""
        return None if not self.candidates else self.candidates[0].view_id

    @property
    def H(self) -> np.ndarray | None:
        """Map from the best trained view's pixels to the query's (for the object pose)."""
        return None if not self.candidates else self.candidates[0].H


def _check_unit(value: object, name: str) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float | np.floating | np.integer):
        raise ValueError(f"{name} must be a number in [0, 1], got {value!r}")
    v = float(value)
    if not (math.isfinite(v) and 0.0 <= v <= 1.0):
        raise ValueError(f"{name} must be a finite number in [0, 1], got {value!r}")
    return v


def resolve_threshold(
    threshold: float | ThresholdChoice | None,
) -> tuple[float, Mapping[str, float]]:
    """``(global, per_model)`` thresholds from a number, a :class:`ThresholdChoice` or
    ``None`` (:data:`DEFAULT_THRESHOLD`); raises ``ValueError`` on anything else."""
    if threshold is None:
        return DEFAULT_THRESHOLD, {}
    if isinstance(threshold, ThresholdChoice):
        return threshold.threshold, threshold.per_model
    return _check_unit(threshold, "threshold"), {}


def decide(
    scores: Mapping[str, float],
    *,
    threshold: float | ThresholdChoice | None = None,
    margin: float = DEFAULT_MARGIN,
) -> tuple[str, str | None, tuple[str, ...]]:
    """The decision rule of section 3.5.1 with the ambiguity margin (module docstring).

    Parameters
    ----------
    scores : mapping of str to float
        Score in [0, 1] per model.
    threshold : float or ThresholdChoice, optional
        Global threshold, or a choice with per-model thresholds (default
        :data:`DEFAULT_THRESHOLD`). A model passes when its score is strictly above.
    margin : float
        Relative margin in [0, 1): ambiguous when runner-up >= (1 - margin) * best.

    Returns
    -------
    decision : str
    model : str or None
        The recognised model, ``None`` otherwise.
    contenders : tuple of str
        Passing models within the margin of the best, best first.
    """
    glob, per_model = resolve_threshold(threshold)
    return decide_with(scores, glob, per_model, margin=margin)


def decide_with(
    scores: Mapping[str, float],
    threshold: float,
    per_model: Mapping[str, float],
    *,
    margin: float = DEFAULT_MARGIN,
) -> tuple[str, str | None, tuple[str, ...]]:
    """:func:`decide` with the thresholds given as a global value and a per-model mapping."""
    glob = threshold
    margin = _check_unit(margin, "margin")
    if margin >= 1.0:
        raise ValueError(f"margin must be below 1, got {margin!r}")
    ranked = sorted(scores.items(), key=lambda kv: (-kv[1], kv[0]))
    for m, s in ranked:
        _check_unit(s, f"score of {m!r}")
    if not ranked or ranked[0][1] <= per_model.get(ranked[0][0], glob):
        return "unknown", None, ()
    best_model, best = ranked[0]
    near = [m for m, s in ranked[1:] if s > 0.0 and s >= (1.0 - margin) * best]
    if near:
        passing = [m for m in near if scores[m] > per_model.get(m, glob)]
        return "ambiguous", None, (best_model, *passing)
    return "recognized", best_model, (best_model,)


def _clutter(H: np.ndarray, view: Features, query: Features, n_inliers: int) -> float:
    hull = cv2.convexHull(np.ascontiguousarray(view.keypoints.xy, dtype=np.float32))
    outline = cv2.perspectiveTransform(hull.reshape(-1, 1, 2), H.astype(np.float64))
    outline = outline.astype(np.float32)
    inside = sum(
        cv2.pointPolygonTest(outline, (float(x), float(y)), False) >= 0
        for x, y in query.keypoints.xy
    )
    if inside == 0:
        return 1.0
    return float(min(1.0, max(0.0, 1.0 - n_inliers / inside)))


def verify_view(index: ViewIndex, view_id: int, query: Features, votes: float = 0.0) -> Candidate:
    """Register one trained view onto the query features and score it (module docstring)."""
    view = index.view(view_id)
    a = view.features
    empty = Candidate(
        view.model, view_id, view.viewpoint, 0.0, 0.0, 0.0, 0.0, 1.0, 0, 0, votes, None
    )
    if len(query) < 3:
        return empty
    m = match(a, query, ratio=DEFAULT_RATIO, mutual=True, method="exact")
    ver = verify(m, a, query, model=index.geometry, reproj_px=REPROJ_PX)
    score, sat, ratio, cov = registration_score(ver, m, a)
    if ver.H is None:
        return Candidate(
            view.model, view_id, view.viewpoint, 0.0, 0.0, 0.0, 0.0, 1.0, 0, len(m), votes, None
        )
    n = ver.n_inliers
    keep = m.index_a[ver.inliers], m.index_b[ver.inliers]
    pairs = np.hstack([a.keypoints.xy[keep[0]], query.keypoints.xy[keep[1]]]).astype(np.float64)
    pairs.setflags(write=False)
    return Candidate(
        view.model,
        view_id,
        view.viewpoint,
        score,
        sat,
        ratio,
        cov,
        _clutter(ver.H, a, query, n),
        n,
        len(m),
        votes,
        ver.H,
        pairs,
    )


def evaluate(
    index: ViewIndex,
    query: Features,
    *,
    viewpoint: int | tuple[int, ...] | None = 1,
    models: Sequence[str] | None = None,
    exclude_view: int | None = None,
    exclude_models: Sequence[str] = (),
    max_models: int = 4,
    views_per_model: int = 2,
) -> tuple[dict[str, float], list[Candidate], float, float]:
    """Scores of every searched model: ``(scores, candidates best first, t_retrieve, t_verify)``.

    The building block of :func:`recognise`, the threshold selection (leave-one-out) and the
    viewpoint policies.
    """
    t0 = time.perf_counter()
    searcher = index.searcher(viewpoint=viewpoint, exclude_models=exclude_models)
    if searcher is None:
        return {}, [], time.perf_counter() - t0, 0.0
    names = searcher.models if models is None else [m for m in searcher.models if m in models]
    scores = dict.fromkeys(names, 0.0)
    if not names or len(query) == 0:
        return scores, [], time.perf_counter() - t0, 0.0
    votes = searcher.votes(
        query, k=DEFAULT_K, models=None if models is None else names, exclude_view=exclude_view
    )
    # Best views per model, models ranked by their best view's votes; beyond its
    # ``views_per_model`` views, a model's next-voted views while its budget lasts.
    order = np.argsort(-votes, kind="stable")
    floor = max(MIN_VOTES, REL_VOTES * float(votes[order[0]]))
    budget = views_per_model * VERIFY_FEATURES
    chosen: dict[str, list[int]] = {}
    spent: dict[str, int] = {}
    for pos in order:
        if votes[pos] < floor:
            break
        v = searcher.views[pos]
        if v.view_id == exclude_view or v.model not in scores:
            continue
        picks = chosen.get(v.model)
        if picks is None:
            if len(chosen) >= max_models:
                continue
            picks = chosen[v.model] = []
            spent[v.model] = 0
        cost = len(v.features)
        if len(picks) < views_per_model or (
            len(picks) < MAX_VIEWS_VERIFIED and spent[v.model] + cost <= budget
        ):
            picks.append(pos)
            spent[v.model] += cost
        if len(chosen) >= max_models and all(
            len(p) >= MAX_VIEWS_VERIFIED or (len(p) >= views_per_model and spent[m] >= budget)
            for m, p in chosen.items()
        ):
            break
    t1 = time.perf_counter()
    best: dict[str, Candidate] = {}
    for _model, picks in chosen.items():
        for pos in picks:
            c = verify_view(index, searcher.views[pos].view_id, query, float(votes[pos]))
            if c.model not in best or c.score > best[c.model].score:
                best[c.model] = c
    for m, c in best.items():
        scores[m] = c.score
    cands = sorted((c for c in best.values() if c.H is not None), key=lambda c: (-c.score, c.model))
    return scores, cands, t1 - t0, time.perf_counter() - t1


def recognise(
    index: ViewIndex,
    image: np.ndarray | Features,
    *,
    viewpoint: int | None = 1,
    mask: np.ndarray | None = None,
    threshold: float | ThresholdChoice | None = None,
    margin: float = DEFAULT_MARGIN,
    models: Sequence[str] | None = None,
    max_models: int = 4,
    views_per_model: int = 2,
    search: tuple[int, ...] | None = None,
) -> Recognition:
    """Recognise the object in ``image`` among the trained views of ``viewpoint``.

    Parameters
    ----------
    index : ViewIndex
        Trained views.
    image : ndarray (H, W[, 3]) uint8 or Features
        The run-time image (RGB or grey), or features already extracted from it with the
        index's method (then ``mask`` must be ``None``).
    viewpoint : int or None
        Compare with the trained views of this viewpoint (1 = top, 2, 3); ``None`` compares
        with every trained view (the chapter's Figure 6).
    mask : ndarray (H, W) bool or uint8, optional
        Object region from segmentation: features are detected inside it only.
    threshold : float in [0, 1] or ThresholdChoice, optional
        Global threshold, or the result of :func:`choose_threshold` (its per-model thresholds
        of ``viewpoint``, see :meth:`ThresholdChoice.at`; pooled ones when ``viewpoint`` is
        ``None``); default :data:`DEFAULT_THRESHOLD`.
    margin : float
        Relative confusion margin in [0, 1) (module docstring).
    models : sequence of str, optional
        Only consider these models (the side-view check of section 3.5.3).
    max_models, views_per_model : int
        Verification budget: best-voted models (1..16) and the views verified per model
        at least (1..8); more of a model's voted views are verified while their features
        fit ``views_per_model`` times :data:`VERIFY_FEATURES`.
    search : tuple of int, optional
        Viewpoints whose trained views are compared (default: ``viewpoint`` alone; the
        thresholds stay those of ``viewpoint``). The side policies search both side
        viewpoints: the inner view of an object turned by 180 degrees is its outer view.

    Returns
    -------
    Recognition
        Frozen result with the decision, every model's score and the best view's ``H``.

    Raises
    ------
    ValueError
        Bad image, mask, viewpoint, threshold, margin or budget; features of another method.
    """
    if not isinstance(index, ViewIndex):
        raise ValueError(f"index must be a ViewIndex, got {type(index).__name__}")
    viewpoint = check_viewpoint(viewpoint, allow_none=True)
    for name, value, hi in (
        ("max_models", max_models, 16),
        ("views_per_model", views_per_model, 8),
    ):
        if isinstance(value, bool) or not isinstance(value, int) or not 1 <= value <= hi:
            raise ValueError(f"{name} must be an int in 1..{hi}, got {value!r}")
    if isinstance(threshold, ThresholdChoice) and viewpoint is not None:
        threshold = threshold.at(viewpoint)
    glob, per_model = resolve_threshold(threshold)
    _check_unit(margin, "margin")
    if models is not None and (
        isinstance(models, str) or not all(isinstance(m, str) for m in models)
    ):
        raise ValueError(f"models must be a sequence of model names, got {models!r}")
    if search is not None:
        if viewpoint is None or not isinstance(search, tuple) or viewpoint not in search:
            raise ValueError(
                f"search must be a tuple of viewpoints including viewpoint {viewpoint!r}, "
                f"got {search!r}"
            )
        for v in search:
            check_viewpoint(v)
    query = index.features(image, mask=mask)
    scores, cands, t_r, t_v = evaluate(
        index,
        query,
        viewpoint=viewpoint if search is None else search,
        models=models,
        max_models=max_models,
        views_per_model=views_per_model,
    )
    decision, model, contenders = decide(scores, threshold=threshold, margin=margin)
    ranked = sorted(scores, key=lambda m: (-scores[m], m))
    best = ranked[0] if ranked and scores[ranked[0]] > 0.0 else None
    return Recognition(
        decision=decision,
        model=model,
        best_model=best,
        score=0.0 if best is None else scores[best],
        scores=MappingProxyType(scores),
        contenders=contenders,
        candidates=tuple(cands),
        threshold=per_model.get(best, glob) if best is not None else glob,
        margin=float(margin),
        viewpoint=viewpoint,
        n_features=len(query),
        retrieval_s=t_r,
        verification_s=t_v,
    )
