"""Automatic threshold selection (the chapter's section 6: "An automatic threshold selection
process can also be implemented. This will eliminate the need to manually select a
threshold").

Score distributions, from the trained views alone
    *Genuine*: every trained view is held out in turn and recognised against the others of
    its viewpoint (leave-one-view-out; side views against the views of both sides, as
    :func:`recognise_views` searches them); its own model's score is a genuine score.
    *Impostor*: every model is held out in turn and each of its views is recognised against
    the remaining models (leave-one-model-out): the best score any other model gets is what
    an untrained object would score. Negative images (nothing trained in them), when given,
    add impostor scores against every model. Scores of the held-out view's *twins* (below)
    are left out of the thresholds: a twin explains the view as well as its own model
    because the two look alike from there (a part on two bases, two wheels with the same
    face), which the decision's ambiguity margin and the side views resolve; kept in, one
    pair of look-alikes among twelve models puts the largest impostor score, and so the
    conformal threshold, at the genuine level (every trained object unknown).

Rules
    ``"conformal-far"`` (default): the global threshold ``t`` is the ``k``-th smallest of the
    ``n`` impostor scores with ``k = ceil((n + 1) * (1 - target_far))``. If a new impostor
    score is exchangeable with those ``n``, ``P(score > t) <= 1 - k / (n + 1) <=
    target_far`` (the finite-sample split-conformal bound: Vovk, Gammerman and Shafer,
    "Algorithmic Learning in a Random World", 2005; Angelopoulos and Bates, "A gentle
    introduction to conformal prediction", 2021, section 1). Views of one object are not
    independent draws, so the bound is a design figure, checked on unknown objects by
    ``benchmarks/recognition.py``. With fewer than ``1 / target_far - 1`` impostor scores
    the bound cannot be reached; the largest impostor score is taken and the choice says so.
    ``"youden"``: the threshold maximising Youden's J = TPR - FPR (Youden, "Index for rating
    diagnostic tests", Cancer 3(1), 1950) over the observed scores.

Per-model thresholds
    ``per_model[m] = max(global, the same rule on the scores model m gave to other models'
    views, its twins' views left out)``: a model that attracts impostors gets a higher bar;
    no model gets a lower one, so the false-accept rate of the whole decision stays that of
    the global rule.

Own bars
    ``own_viewpoint[vp][m]``: the rule on the scores model ``m`` gave to the other models'
    views of viewpoint ``vp`` alone (its twins' views left out), at most ``per_viewpoint[vp]``;
    ``per_viewpoint[vp]`` itself when ``m`` has fewer than :data:`MIN_OWN_IMPOSTORS` such
    scores (the largest of ``n`` exchangeable scores is beaten by a new one with probability
    ``1 / (n + 1)``: with too few it bounds nothing). With the conformal rule and under 99
    scores it is the largest score ``m`` gave to any other model's view there: a plain part
    that never verifies other parts gets a low bar, a wheel that verifies other wheels a
    high one, whereas the global bar of a side viewpoint is set by the model most prone to
    verify others (a wheel: 0.264, where plain parts verify with 8-12 inliers, 0.1-0.2).
    An own bar is never below the rule on the scores of every model pooled (each model's
    scores to the other models' views, some thousand at a side viewpoint): a model that
    verified none of its 40-130 impostor views (own maximum 0, plain parts) has a
    false-accept rate of perhaps under 1 %, not 0, and a bar of 0 would pass any
    verification at all; the pooled rule estimates how high an impostor scores against
    one model at the target rate. Each own bar bounds that model's false accepts alone;
    over the models verified on one view the bound adds up, so they are not acceptance
    bars on their own: the policies use them where a decision already has a first test
    behind it (a side view checking the contenders of the top view, the top view
    shortlisting models for a side view).

Per viewpoint
    The same rule on the scores of each viewpoint alone gives ``per_viewpoint[vp]`` and
    ``per_model_viewpoint[vp][m]``; :meth:`ThresholdChoice.at` returns the choice for one
    viewpoint, which :func:`recognise` applies when it searches one viewpoint. *Twins* are
    the other models that explained a held-out view about as well as its own model did
    (within the ambiguity margin :data:`DEFAULT_MARGIN`, or better) in the leave-one-view-out
    run: indistinguishable from it at that viewpoint, so their scores say nothing about an
    untrained object, and they are left out of every threshold (see *Impostor*). Models
    alike from the top then both pass there and the top view is ``ambiguous``: a side view
    must decide. ``candidate`` is the bar for *considering* a model worth a side view (the
    same rule on the twin-free scores, so now equal to ``threshold``; kept for the policies).

One model
    With a single model there is no other model to hold out, so its impostor scores come
    from negative images alone (the empty belt, other things in the scene): each scores
    against the model as an untrained object would.  Without negatives there is nothing
    to bound the false accepts with, and the choice is refused with that advice.

Floor and advice
    An automatic threshold is never below :data:`THRESHOLD_FLOOR`: when no impostor
    verified at all (few or featureless negatives, models unlike each other) the rule
    would give 0, which accepts any verification of a handful of chance matches.  The
    floor is applied by :func:`floor_threshold`, the one place that decides it, to every
    acceptance bar (global, per model, per viewpoint, candidate); own bars are not
    acceptance bars on their own and keep their pooled floor.  When the scores cannot support the target false-accept
    rate (too few impostor scores for the bound, the floor taken, views without a genuine
    score, many trained views rejected) :attr:`ThresholdChoice.advice` says in plain words
    what to add: more views, more models or negative images.

Confusability
    ``confusion[viewpoint][a][b]``: share of model ``a``'s held-out views of that viewpoint on
    which model ``b`` scores above the viewpoint's ``candidate`` bar (would be considered). Models alike from the top (viewpoint 1) need a
    side view; ``best-next`` picks the side viewpoint where the remaining candidates are least
    alike.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from collections.abc import Set as AbstractSet

import numpy as np
from numpy.typing import ArrayLike

from vision.features import Features
from vision.recognition.choice import ThresholdChoice, roc_curve
from vision.recognition.index import ViewIndex
from vision.recognition.recognise import DEFAULT_MARGIN, evaluate, search_of

__all__ = [
    "RULES",
    "THRESHOLD_FLOOR",
    "ThresholdChoice",
    "choose_threshold",
    "conformal_threshold",
    "floor_threshold",
    "youden_threshold",
]

RULES = ("conformal-far", "youden")
MAX_NEGATIVES = 10_000
#: Fewest impostor scores of a model at a viewpoint for its own bar (module docstring):
#: the largest of 20 is beaten by a new exchangeable score with probability 1/21 < 5 %.
MIN_OWN_IMPOSTORS = 20
#: Lowest automatic threshold (module docstring, "Floor and advice").  A verification
#: passes it with about six inliers beyond the minimal sample, half of the tentative
#: matches explained and a tenth of the view's feature area covered (saturation 0.26 x
#: sqrt(0.5 x 0.1) = 0.058 > 0.03): chance matches between unrelated images rarely reach
#: that, while genuine COIL-20 views 10 degrees apart score 0.2-0.8.
THRESHOLD_FLOOR = 0.03


def _check_scores(x: object, name: str, *, allow_empty: bool = False) -> np.ndarray:
    a = np.asarray(x, dtype=np.float64).reshape(-1)
    if not allow_empty and a.size == 0:
        raise ValueError(f"{name} scores are empty")
    if not np.all(np.isfinite(a)) or (a.size and (a.min() < 0.0 or a.max() > 1.0)):
        raise ValueError(f"{name} scores must be finite and in [0, 1]")
    return a


def conformal_threshold(impostor: ArrayLike, target_far: float) -> tuple[float, float | None]:
    """Smallest order statistic of ``impostor`` whose finite-sample FAR bound is met.

    Returns ``(threshold, bound)`` with ``bound = 1 - k / (n + 1) <= target_far``; when
    ``n < 1 / target_far - 1`` no order statistic reaches it: ``(max, None)``.
    """
    i = np.sort(_check_scores(impostor, "impostor"))
    if not (0.0 < target_far < 1.0):
        raise ValueError(f"target_far must be in (0, 1), got {target_far!r}")
    n = len(i)
    k = math.ceil((n + 1) * (1.0 - target_far) - 1e-9)
    if k > n:
        return float(i[-1]), None
    return float(i[k - 1]), 1.0 - k / (n + 1)


def youden_threshold(genuine: ArrayLike, impostor: ArrayLike) -> float:
    """Threshold maximising Youden's J = TPR - FAR (ties: the highest such threshold)."""
    g = _check_scores(genuine, "genuine")
    i = _check_scores(impostor, "impostor")
    t, far, tpr = roc_curve(g, i)
    j = tpr - far
    best = np.flatnonzero(j >= j.max() - 1e-12)
    return float(t[best[-1]])


def floor_threshold(threshold: float) -> float:
    """An automatic threshold raised to :data:`THRESHOLD_FLOOR` (module docstring)."""
    return float(max(float(threshold), THRESHOLD_FLOOR))


def _check_far(value: object) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise ValueError(f"target_far must be a number in (0, 0.5], got {value!r}")
    v = float(value)
    if not (math.isfinite(v) and 0.0 < v <= 0.5):
        raise ValueError(f"target_far must be a finite number in (0, 0.5], got {value!r}")
    return v


def _rule(
    genuine: Sequence[float],
    impostor: Sequence[float],
    per_model_imp: Mapping[str, Sequence[float]],
    models: Sequence[str],
    *,
    rule: str,
    target_far: float,
) -> tuple[float, float | None, str, dict[str, float]]:
    """``(threshold, bound, text, per_model)`` of one rule on one set of scores."""
    g = np.asarray(genuine, dtype=np.float64)
    i = np.asarray(impostor, dtype=np.float64)
    n = len(i)
    if rule == "conformal-far":
        t, bound = conformal_threshold(i, target_far)
        if bound is None:
            text = (
                f"conformal FAR <= {target_far:g} not reachable with {n} impostor scores "
                f"(need {math.ceil(1 / target_far - 1)}): threshold = largest impostor score"
            )
        else:
            k = math.ceil((n + 1) * (1 - target_far) - 1e-9)
            text = (
                f"conformal FAR <= {target_far:g}: {k}-th of {n} impostor scores, bound {bound:.4f}"
            )
    else:
        t, bound = youden_threshold(g, i), None
        text = f"Youden's J over {len(g)} genuine and {n} impostor scores"
    if t < THRESHOLD_FLOOR:
        text += f"; raised to the floor {THRESHOLD_FLOOR:g} (the rule gave {t:.3f})"
        t = floor_threshold(t)
    per_model: dict[str, float] = {}
    for m in models:
        imp = per_model_imp.get(m, [])
        tm = conformal_threshold(imp, target_far)[0] if imp and rule == "conformal-far" else t
        per_model[m] = max(t, tm)
    return float(t), bound, text, per_model


def _candidate(
    genuine: Sequence[float], distinct: Sequence[float], *, rule: str, target_far: float, cap: float
) -> float:
    """The rule on the impostor scores without twins, at most ``cap``."""
    if rule == "conformal-far":
        c = conformal_threshold(distinct, target_far)[0]
    else:
        c = youden_threshold(genuine, distinct)
    return float(min(floor_threshold(c), cap))


def _own_bars(
    imp_vp: Mapping[str, Sequence[float]],
    models: Sequence[str],
    cap: float,
    *,
    rule: str,
    target_far: float,
) -> dict[str, float]:
    """Own bars of one viewpoint (module docstring, "Own bars"): the rule on each model's
    impostor scores, not below the rule on every model's pooled, at most ``cap``."""
    if rule != "conformal-far":
        return {m: float(cap) for m in models}
    pooled = [s for m in models for s in imp_vp.get(m, [])]
    if not pooled:
        return {m: float(cap) for m in models}
    floor = conformal_threshold(pooled, target_far)[0]
    out: dict[str, float] = {}
    for m in models:
        imp = imp_vp.get(m, [])
        if len(imp) < MIN_OWN_IMPOSTORS:
            out[m] = float(cap)
        else:
            out[m] = float(min(cap, max(floor, conformal_threshold(imp, target_far)[0])))
    return out


def choose_threshold(
    index: ViewIndex,
    *,
    negatives: Sequence[np.ndarray | Features] | None = None,
    target_far: float = 0.01,
    rule: str = "conformal-far",
    progress: Callable[[int, int], None] | None = None,
    exclude_twins: bool = True,
) -> ThresholdChoice:
    """Choose global and per-model thresholds from the trained views (module docstring).

    Parameters
    ----------
    index : ViewIndex
        At least two models (or one model and ``negatives``), and at least two views of
        one model in some viewpoint.
    negatives : sequence of images or Features, optional
        Images of things that are none of the models (empty belt, other parts); each gives
        one impostor score per viewpoint (its best model) and per-model scores.
    target_far : float
        Target false-accept rate in (0, 0.5] for ``rule="conformal-far"``.
    rule : {"conformal-far", "youden"}
    progress : callable(done, total), optional
        Called after each held-out query.
    exclude_twins : bool
        Leave the twins' scores out of the thresholds (default; module docstring).
        ``False`` keeps them in: the earlier rule, kept for comparison only.

    Returns
    -------
    ThresholdChoice

    Raises
    ------
    ValueError
        No model, one model without negatives, no model with two views of a viewpoint, a
        bad rule, target or negative image.
    """
    if not isinstance(index, ViewIndex):
        raise ValueError(f"index must be a ViewIndex, got {type(index).__name__}")
    if rule not in RULES:
        raise ValueError(f"rule must be one of {RULES}, got {rule!r}")
    if not isinstance(exclude_twins, bool):
        raise ValueError(f"exclude_twins must be true or false, got {exclude_twins!r}")
    target_far = _check_far(target_far)
    models = index.models
    negs = list(negatives or [])
    if not models or (len(models) < 2 and not negs):
        have = f"only {models[0]}" if models else "none"
        raise ValueError(
            f"threshold selection needs at least two models, or one model and negative images "
            f"(the empty belt, other things in the scene); the index has {have}"
        )
    if len(negs) > MAX_NEGATIVES:
        raise ValueError(f"at most {MAX_NEGATIVES} negative images, got {len(negs)}")
    neg_feats = [index.features(x) for x in negs]
    views = index.views
    viewpoints = sorted({v.viewpoint for v in views})
    total = 2 * len(views) + len(neg_feats) * len(viewpoints)
    done = 0

    def tick() -> None:
        nonlocal done
        done += 1
        if progress is not None:
            progress(done, total)

    # Genuine: leave one view out.
    genuine: list[float] = []
    genuine_models: list[str] = []
    genuine_vps: list[int] = []
    twins: dict[int, set[str]] = {}
    lovo: list[tuple[int, str, dict[str, float]]] = []
    for v in views:
        pool = search_of(v.viewpoint)  # as recognise_views searches (the sides pooled)
        others = [w for w in index.views_of(v.model) if w.viewpoint in pool and w is not v]
        if others:
            scores, *_ = evaluate(index, v.features, viewpoint=pool, exclude_view=v.view_id)
            genuine.append(scores.get(v.model, 0.0))
            genuine_models.append(v.model)
            genuine_vps.append(v.viewpoint)
            lovo.append((v.viewpoint, v.model, scores))
            g_v = scores.get(v.model, 0.0)
            # Models explaining the held-out view about as well as its own model does (within
            # the decision's ambiguity margin, or better) are indistinguishable from it at this
            # viewpoint ("twins").
            twins[v.view_id] = {
                b
                for b, s in scores.items()
                if b != v.model and s > 0 and s >= (1.0 - DEFAULT_MARGIN) * g_v
            }
        tick()
    if not genuine:
        raise ValueError("no model has two trained views of one viewpoint: nothing to hold out")
    # Impostor: leave one model out (and negatives).
    impostor: list[float] = []
    impostor_vps: list[int] = []
    per_model_imp: dict[str, list[float]] = {m: [] for m in models}
    per_model_imp_vp: dict[str, list[tuple[float, int]]] = {m: [] for m in models}

    distinct: list[float] = []

    def add_impostor(
        scores: dict[str, float], vp: int, twin: AbstractSet[str] = frozenset()
    ) -> None:
        impostor.append(max(scores.values(), default=0.0))
        distinct.append(max((s for m, s in scores.items() if m not in twin), default=0.0))
        impostor_vps.append(vp)
        for m, s in scores.items():
            if m in twin:  # a look-alike of the held-out model: not an untrained object's score
                continue
            per_model_imp[m].append(s)
            per_model_imp_vp[m].append((s, vp))

    for v in views:
        if len(models) > 1:  # one model: nothing is left when it is held out
            scores, *_ = evaluate(
                index, v.features, viewpoint=search_of(v.viewpoint), exclude_models=[v.model]
            )
            twin = twins.get(v.view_id, set()) if exclude_twins else set()
            add_impostor(scores, v.viewpoint, twin)
        tick()
    for f in neg_feats:
        for vp in viewpoints:
            scores, *_ = evaluate(index, f, viewpoint=search_of(vp))
            add_impostor(scores, vp)
            tick()
    # Acceptance thresholds from the impostor scores without twins (module docstring): a
    # twin's score says the two models look alike there, which the ambiguity margin and the
    # side views handle, not how high an untrained object scores.
    t, bound, text, per_model = _rule(
        genuine, distinct, per_model_imp, models, rule=rule, target_far=target_far
    )
    cand = _candidate(genuine, distinct, rule=rule, target_far=target_far, cap=t)
    per_vp: dict[int, float] = {}
    per_model_vp: dict[int, dict[str, float]] = {}
    cand_vp: dict[int, float] = {}
    own_vp: dict[int, dict[str, float]] = {}
    for vp in viewpoints:
        g_vp = [s for s, v in zip(genuine, genuine_vps, strict=True) if v == vp]
        i_vp = [s for s, v in zip(impostor, impostor_vps, strict=True) if v == vp]
        if not g_vp or not i_vp:
            continue
        d_vp = [s for s, v in zip(distinct, impostor_vps, strict=True) if v == vp]
        imp_vp = {m: [s for s, v in per_model_imp_vp[m] if v == vp] for m in models}
        tv, _, _, pm = _rule(g_vp, d_vp, imp_vp, models, rule=rule, target_far=target_far)
        per_vp[vp], per_model_vp[vp] = tv, pm
        cand_vp[vp] = _candidate(g_vp, d_vp, rule=rule, target_far=target_far, cap=tv)
        own_vp[vp] = _own_bars(imp_vp, models, tv, rule=rule, target_far=target_far)
    g = np.asarray(genuine)
    i = np.asarray(impostor)
    advice = _advice(
        index, n_impostor=len(distinct), bound=bound, rule=rule, target_far=target_far,
        raw=float(t), frr=float(np.mean(g <= t)), n_negatives=len(neg_feats),
    )  # fmt: skip
    confusion: dict[int, dict[str, dict[str, float]]] = {}
    counts: dict[tuple[int, str], int] = {}
    for vp, a, scores in lovo:
        counts[(vp, a)] = counts.get((vp, a), 0) + 1
        row = confusion.setdefault(vp, {}).setdefault(a, {})
        for b, s in scores.items():
            if b != a:
                row[b] = row.get(b, 0.0) + float(s > cand_vp.get(vp, cand))
    for (vp, a), c in counts.items():
        row = confusion[vp][a]
        for b in row:
            row[b] /= c
    return ThresholdChoice(
        threshold=float(t),
        per_model=per_model,
        rule=text,
        rule_id=rule,
        target_far=target_far if rule == "conformal-far" else None,
        far_bound=bound,
        far=float(np.mean(np.asarray(distinct) > t)),
        frr=float(np.mean(g <= t)),
        genuine=g,
        impostor=i,
        genuine_models=tuple(genuine_models),
        confusion=confusion,
        candidate=cand,
        per_viewpoint=per_vp,
        per_model_viewpoint=per_model_vp,
        candidate_viewpoint=cand_vp,
        own_viewpoint=own_vp,
        advice=advice,
    )


#: Share of rejected trained views above which the advice asks for more views.
ADVICE_FRR = 0.05


def _advice(
    index: ViewIndex,
    *,
    n_impostor: int,
    bound: float | None,
    rule: str,
    target_far: float,
    raw: float,
    frr: float,
    n_negatives: int,
) -> tuple[str, ...]:
    """What to add so that the scores support the target (module docstring), in words."""
    out: list[str] = []
    models = index.models
    if rule == "conformal-far" and bound is None:
        need = math.ceil(1 / target_far - 1)
        out.append(
            f"Add impostors: a false-accept rate of at most {target_far:.0%} needs at least "
            f"{need} impostor scores and there are {n_impostor}. Each view of another model "
            "gives one and each negative image one per viewpoint: add more models, more "
            "views of them, or negative images (the empty belt, other things in the scene)."
        )
    if raw <= THRESHOLD_FLOOR:
        out.append(
            f"No impostor scored above {THRESHOLD_FLOOR:g}, so the threshold is the floor "
            f"{THRESHOLD_FLOOR:g} rather than a measured value: add negative images (the "
            "empty belt, other things in the scene) or more models so that it rests on data."
        )
    if len(models) == 1 and n_negatives < 20:
        out.append(
            f"Only one model ({models[0]}) and {n_negatives} negative images: add a second "
            "model or more negative images."
        )
    for m in models:
        per_vp: dict[int, int] = {}
        for v in index.views_of(m):
            per_vp[v.viewpoint] = per_vp.get(v.viewpoint, 0) + 1
        lone = sorted(vp for vp, c in per_vp.items() if c < 2)
        if lone:
            out.append(
                f"Model {m} has a single view of viewpoint {', '.join(map(str, lone))}: add "
                "more views there so that its own scores can be measured."
            )
    if frr > ADVICE_FRR:
        out.append(
            f"{frr:.0%} of the trained views score at or below the threshold against the "
            "other views of their model: add more views of the models (smaller turns between "
            "them) so that known objects are not rejected."
        )
    return tuple(out)
