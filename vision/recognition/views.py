"""3D recognition over viewpoints (chapter sections 3.5.2 and 3.5.3, Figures 6 and 7).

``recognise_views(look, index, policy=...)`` asks the caller for images, ``look(viewpoint)``,
and decides after one, two or three of them. ``look`` may be a plain function or a coroutine
function (the cell's moves the arm); it returns an image, an ``(image, mask)`` pair, or
:class:`vision.features.Features`. The recognition itself runs in a worker thread so that an
event loop driving the robot stays responsive.

Policies
    ``naive`` (Figure 6): every view against every trained image of every viewpoint; stop at
    the first view where exactly one model is recognised; otherwise look again. The chapter's
    loop never ends on an untrained object; here it stops after ``max_views``.
    ``top-only``: decide from viewpoint 1 alone (the 2D algorithm of section 3.5.1).
    ``two-views`` (section 3.5.3, the chapter's choice): top view against the top views of
    every model. A model the top view names alone is checked with side view 2 (and 3 if
    view 2 neither confirms nor contradicts it) against the side views of itself and its
    *challengers* (the other models above their shortlist bar from the top, and those
    confused with it from the top); it stays named unless a side view is won by a
    challenger (see "Fused score"). When the top view is ambiguous, its contenders (the
    passing best and the models within the margin of it), or, when no model passes, every
    model above its *shortlist bar* (the lower of the choice's candidate bar and the
    model's own top bar, "Own bars" below), are verified with side view 2 against the side views of the
    contenders only (those of both side viewpoints: the arm sees an object from two azimuths
    only, and the inner view of an object turned by 180 degrees is its outer view), and
    with view 3 if still uncertain: the fused decision must recognise a model that also
    passes its own bar on a side view; fail after three. Nothing above its shortlist bar
    from the top: unknown after one view.
    ``best-next`` (beyond the chapter): like ``two-views``, but a model recognised from the
    top that no other model is confused with from the top (confusion table of
    :func:`choose_threshold`, below ``confusion_limit``) is accepted at once, and the side
    viewpoint visited next is the one where the remaining contenders are least confused.

Fused score
    After several views, a model's score is the mean of its scores over the visited views
    (0 where it was not verified), and its threshold the mean of its thresholds there
    (:meth:`ThresholdChoice.at` each viewpoint); the decision rule of section 3.5.1 is
    applied to them. A top view that passes no threshold still sends the models above the
    choice's ``candidate`` bar (the best :data:`MAX_CONTENDERS`) to a side view, and then only
    the side views are fused: models alike from the top raise the top threshold beyond
    reach, and only a side view can decide; the winner must also pass its own bar on a side
    view.

    A model named by the top view alone is not put to the fused score. Its top
    score passed a bar set above the impostor scores of the top views (the conformal rule
    of :func:`choose_threshold`; with fewer than 199 impostor scores at the default 1 %
    target it is the largest score any other model's top view got), so the top view already bounds how often an untrained
    object is named; what the side views add is the chapter's check against look-alikes.
    A side view where neither it nor a challenger verifies (the object seen at a yaw whose
    side was never taught verifies little) is no evidence either way, whereas fused as 0 it
    dragged a clear top score (0.295 against a bar of 0.107) under the mean bar (0.098
    against 0.160). So: the model is confirmed by a side view where it passes its bar (or
    the fused decision names it); it is *overturned* by a side view won by a challenger
    (the challenger passes its own side bar there and beats the model's score), after which
    the models seen are decided as after an ambiguous top view (the fused decision, a
    winner passing its own side bar, else ``ambiguous`` and the colour tie-break); if no
    side view does either, it stays named. Untrained objects stay guarded where the top
    view did not name one model alone (only shortlisted, or look-alikes within the margin
    such as the twin wheels): there the side views decide exactly as before.

Own bars
    On a side view a model's bar is its own bar there (``ThresholdChoice.own``: from the
    scores it gave the other models' views, never below the pooled rule, at most the
    viewpoint's bar; :func:`choose_threshold`, "Own bars"), not the viewpoint's global bar:
    that one is set by the model most prone to verify others (side 2: 0.264, a wheel's),
    and plain parts that verify with 8-12 inliers (0.1-0.2) never passed it. The fused bar
    is the mean of these bars. Own bars are not acceptance bars on their own (over the
    models verified on a view their false-accept bounds add up), so they apply only where
    the top view has already tested the object: on the side views that check its
    contenders, and to shortlist models for them; a name from the top view alone still
    needs the top view's acceptance bar.

Grey look-alikes
    Two models whose grey features cannot be told apart at a side viewpoint (the confusion
    table of :func:`choose_threshold`: each passes the candidate bar on more than
    :data:`LOOKALIKE_SHARE` of the other's held-out views there; the 5-spoke wheel and its
    red-band twin) differ in their grey side scores by chance only, and under dimmed light
    or a colour cast the inspection named the wrong twin on such a difference. When the
    model a side view would confirm or name has a look-alike there that verified too, the
    side views stop deciding between them: they go to the colour tie-break as tied models,
    and without colour evidence the answer is ``ambiguous``. The look ends there only when
    colour already singles one out; otherwise the remaining side viewpoint is visited for
    colour evidence alone (its grey scores still decide nothing between the look-alikes):
    the first side view may show the twins' difference poorly, or the true twin may verify
    there only below its own bar, which the tie-break requires on some side view
    (``benchmarks.inspection``: the plain five-spoke wheel ended ``ambiguous`` after one
    side view, its red-band twin named from the top and not confirmed). For the same reason
    the ambiguity margin, which narrows the models checked on the next side view to the
    contenders, keeps a look-alike of a contender that verified on this one, and when the
    side views end without a decision the fused leader's look-alikes verified on any side
    view are tied with it for colour, however far below it their grey scores fell (at
    constant belt speed the plain wheel ended "its twin not confirmed" after both side
    views: the answer this path gives once the margin has dropped the wheel).

Colour tie-break
    The features are grey, so two models that differ only by colour (a red band on a tyre's
    tread) stay within the ambiguity margin after every side view. When the side views end
    ``ambiguous``, each model within the margin of the best fused score is compared by colour
    on the side views where it was verified: the signature of the query region (the outline
    of its best trained view's object region mapped by that view's ``H``) against the
    signature stored with that view (:mod:`vision.recognition.colour`), averaged over those views. The
    most similar model is named only when it beats every other tied model by at least
    :data:`COLOUR_MARGIN`, resembles its own views by at least :data:`COLOUR_MIN`, and passes
    its thresholds as any side-view decision must (its fused bar, and its own bar on a side
    view). Colour never raises a score: an object that no model explains stays ``unknown``.
"""

from __future__ import annotations

import asyncio
import inspect
from collections.abc import Awaitable, Callable, Mapping
from dataclasses import dataclass
from types import MappingProxyType

import numpy as np

from vision.features import Features
from vision.recognition.colour import colour_distance, held_sectors
from vision.recognition.index import ViewIndex, view_colour
from vision.recognition.recognise import (
    DEFAULT_MARGIN,
    Recognition,
    decide,
    decide_with,
    recognise,
    resolve_threshold,
    search_of,
)
from vision.recognition.threshold import ThresholdChoice

__all__ = [
    "COLOUR_MARGIN",
    "COLOUR_MAX",
    "DEFAULT_CONFUSION_LIMIT",
    "POLICIES",
    "ViewsRecognition",
    "colour_support",
    "recognise_views",
]

POLICIES = ("naive", "top-only", "two-views", "best-next")
#: ``best-next`` accepts a top-view recognition when every other model passes on less than
#: this share of the model's held-out top views.
DEFAULT_CONFUSION_LIMIT = 0.05

#: Side views are checked against at most this many contenders from an inconclusive top view.
MAX_CONTENDERS = 8

#: Two models are grey look-alikes at a side viewpoint when each passes the viewpoint's
#: candidate bar on more than half of the other's held-out views there (the confusion table
#: of :func:`choose_threshold`): more often than not the grey features cannot tell them
#: apart, so their grey scores there never decide between them ("Grey look-alikes").
LOOKALIKE_SHARE = 0.5

#: Colour tie-break (module docstring), in the log units of ``colour_distance``: every other
#: tied model must be at least ``COLOUR_MARGIN`` farther than the winner (0.7: about twice
#: or half the share of one hue), and the winner at most ``COLOUR_MAX`` from its own views.
#: Measured on the simulated twins (``benchmarks/recognition_yaw.py``, 4 twin queries): the
#: right wheel's side views at 0.01-0.09, the other wheel's at 2.2-2.4 (the red band is 2-4 %
#: of the inner side view). Strongly coloured parts whose colour shifts between views (the
#: red valve block: 6-14 from its own views) are never decided by colour.
COLOUR_MARGIN = 0.7
COLOUR_MAX = 2.0

LookResult = np.ndarray | Features | tuple[np.ndarray, np.ndarray | None]
Look = Callable[[int], LookResult | Awaitable[LookResult]]


@dataclass(frozen=True, eq=False)
class ViewsRecognition:
    """Result of :func:`recognise_views`.

    Attributes
    ----------
    decision : {"recognized", "ambiguous", "unknown"}
    model : str or None
        The recognised model (``None`` unless recognised).
    score : float
        Fused score of the best model, in [0, 1].
    scores : mapping of str to float
        Fused score of every model considered (mean over visited views).
    contenders : tuple of str
        Models still in contention at the end (several when ambiguous).
    policy : str
    viewpoints : tuple of int
        Viewpoints visited, in order.
    views : tuple of Recognition
        The recognition of each visited view, aligned with ``viewpoints``.
    """

    decision: str
    model: str | None
    score: float
    scores: Mapping[str, float]
    contenders: tuple[str, ...]
    policy: str
    viewpoints: tuple[int, ...]
    views: tuple[Recognition, ...]

    @property
    def n_views(self) -> int:
        """Number of views taken."""
        return len(self.viewpoints)


async def _look(look: Look, viewpoint: int) -> tuple[np.ndarray | Features, np.ndarray | None]:
    got = look(viewpoint)
    if inspect.isawaitable(got):
        got = await got
    if isinstance(got, tuple):
        if len(got) != 2:
            raise ValueError(
                f"look({viewpoint}) returned a tuple of {len(got)}, want (image, mask)"
            )
        return got[0], got[1]
    if isinstance(got, np.ndarray | Features):
        return got, None
    raise ValueError(
        f"look({viewpoint}) must return an image, (image, mask) or Features, "
        f"got {type(got).__name__}"
    )


def _fuse(views: list[Recognition], models: list[str]) -> dict[str, float]:
    return {m: float(np.mean([r.scores.get(m, 0.0) for r in views])) for m in models}


def _side_order(
    index: ViewIndex, contenders: tuple[str, ...], choice: ThresholdChoice | None, smart: bool
) -> list[int]:
    """Side viewpoints where some contender has trained views; ``smart`` sorts them by the
    summed pairwise confusion of the contenders there (least first)."""
    sides = [vp for vp in (2, 3) if any(vp in index.viewpoints_of(m) for m in contenders)]
    if not smart or choice is None:
        return sides

    def cost(vp: int) -> float:
        table = choice.confusion.get(vp, {})
        return sum(table.get(a, {}).get(b, 0.0) for a in contenders for b in contenders if a != b)

    return sorted(sides, key=lambda vp: (cost(vp), vp))


def colour_support(
    index: ViewIndex,
    views: list[Recognition],
    images: list[np.ndarray | None],
    models: list[str],
) -> dict[str, float]:
    """Mean colour distance of each of ``models`` over the side views where it was verified
    and both the query region and its best trained view have a colour signature (module
    docstring), summed over the hue sectors that at least one of the compared trained views
    holds (:func:`vision.recognition.colour.held_sectors`); models without one are left out."""
    pairs: dict[str, list[tuple[np.ndarray, np.ndarray]]] = {}
    for m in models:
        for r, image in zip(views, images, strict=True):
            if r.viewpoint not in (2, 3) or image is None:
                continue
            cand = next((c for c in r.candidates if c.model == m and c.H is not None), None)
            if cand is None:
                continue
            view = index.view(cand.view_id)
            if view.colour is None or view.outline is None:
                continue
            q = view_colour(image, view.outline, H=cand.H, transfer=index.colour_transfer)
            if q is not None:
                pairs.setdefault(m, []).append((q, view.colour))
    # Only the hues some compared view holds tell the models apart (held_sectors).
    held = held_sectors([v for ps in pairs.values() for _, v in ps])
    return {
        m: float(np.mean([colour_distance(q, v, sectors=held) for q, v in ps]))
        for m, ps in pairs.items()
    }


def _top_confusers(choice: ThresholdChoice, model: str, limit: float) -> tuple[str, ...]:
    row = choice.confusion.get(1, {}).get(model, {})
    rows_in = {a: r.get(model, 0.0) for a, r in choice.confusion.get(1, {}).items() if a != model}
    alike = {b for b, c in row.items() if c >= limit} | {
        a for a, c in rows_in.items() if c >= limit
    }
    return tuple(sorted(alike))


async def recognise_views(
    look: Look,
    index: ViewIndex,
    *,
    policy: str,
    max_views: int = 3,
    threshold: float | ThresholdChoice | None = None,
    margin: float = DEFAULT_MARGIN,
    confusion_limit: float = DEFAULT_CONFUSION_LIMIT,
    colour_tiebreak: bool = True,
) -> ViewsRecognition:
    """Recognise a 3D object from up to three viewpoints (module docstring).

    Parameters
    ----------
    look : callable(viewpoint) -> image, (image, mask) or Features; sync or async
        Moves to viewpoint 1, 2 or 3 and returns what the camera sees there.
    index : ViewIndex
        Trained views (top views at viewpoint 1, side views at 2 and 3).
    policy : {"naive", "top-only", "two-views", "best-next"}
    max_views : int
        Views taken at most, 1..3.
    threshold : float or ThresholdChoice, optional
        As for :func:`recognise`; ``best-next`` needs a :class:`ThresholdChoice` (its
        confusion table).
    margin : float
        Relative confusion margin (see :func:`vision.recognition.decide`).
    confusion_limit : float
        ``best-next`` only: top-view confusion share in [0, 1] under which one view suffices.
    colour_tiebreak : bool
        Break a tie left after the side views by colour (module docstring; default on).

    Raises
    ------
    ValueError
        Unknown policy, ``max_views`` outside 1..3, ``best-next`` without a ThresholdChoice,
        or ``look`` returning something that is not an image.
    """
    if policy not in POLICIES:
        raise ValueError(f"policy must be one of {', '.join(POLICIES)}, got {policy!r}")
    if isinstance(max_views, bool) or not isinstance(max_views, int) or not 1 <= max_views <= 3:
        raise ValueError(f"max_views must be an int in 1..3, got {max_views!r}")
    if not isinstance(index, ViewIndex):
        raise ValueError(f"index must be a ViewIndex, got {type(index).__name__}")
    if not callable(look):
        raise ValueError(f"look must be callable, got {type(look).__name__}")
    if policy == "best-next" and not isinstance(threshold, ThresholdChoice):
        raise ValueError("policy 'best-next' needs threshold=ThresholdChoice (its confusion table)")
    if (
        isinstance(confusion_limit, bool)
        or not isinstance(confusion_limit, int | float)
        or not 0.0 <= float(confusion_limit) <= 1.0
    ):
        raise ValueError(f"confusion_limit must be in [0, 1], got {confusion_limit!r}")
    if not isinstance(colour_tiebreak, bool):
        raise ValueError(f"colour_tiebreak must be true or false, got {colour_tiebreak!r}")
    decide({}, threshold=threshold, margin=margin)  # validates threshold and margin before moving
    choice = threshold if isinstance(threshold, ThresholdChoice) else None

    def at(vp: int) -> float | ThresholdChoice | None:
        return choice.at(vp) if choice is not None else threshold

    def bar(model: str, vp: int) -> float:
        """``model``'s bar at ``vp``: its own bar on a side view (module docstring, "Own
        bars"), its acceptance threshold on the top view."""
        if choice is not None and vp in (2, 3):
            return choice.own(model, vp)
        glob, per_model = resolve_threshold(at(vp))
        return per_model.get(model, glob)

    def shortlist(model: str) -> float:
        """Bar above which a top-view score makes ``model`` worth a side view."""
        if choice is None:
            return bar(model, 1)
        return min(choice.at(1).candidate, choice.own(model, 1))

    skip_top = False  # set when the top view only shortlisted (it could not rank)

    def fused_decision(models: list[str]) -> tuple[dict[str, float], tuple]:
        first = 1 if skip_top and len(views) > 1 else 0
        fused = _fuse(views[first:], models)
        bars = {m: float(np.mean([bar(m, vp) for vp in visited[first:]])) for m in models}
        return fused, decide_with(fused, 1.0, bars, margin=margin)

    visited: list[int] = []
    views: list[Recognition] = []
    images: list[np.ndarray | None] = []  # RGB images of the visited views (colour tie-break)

    async def see(vp: int, viewpoint: int | None, models=None) -> Recognition:
        image, mask = await _look(look, vp)
        r = await asyncio.to_thread(
            recognise,
            index,
            image,
            viewpoint=viewpoint,
            mask=mask,
            threshold=at(vp),
            margin=margin,
            models=models,
            search=None if viewpoint is None else search_of(viewpoint),
        )
        visited.append(vp)
        views.append(r)
        images.append(image if isinstance(image, np.ndarray) and image.ndim == 3 else None)
        return r

    def result(
        decision: str, model: str | None, scores: dict[str, float], cont
    ) -> ViewsRecognition:
        best = max(scores.values(), default=0.0)
        return ViewsRecognition(
            decision=decision,
            model=model,
            score=float(scores[model]) if model is not None else float(best),
            scores=MappingProxyType(dict(scores)),
            contenders=tuple(cont),
            policy=policy,
            viewpoints=tuple(visited),
            views=tuple(views),
        )

    def single(r: Recognition) -> ViewsRecognition:
        return result(r.decision, r.model, dict(r.scores), r.contenders)

    if policy == "naive":
        for vp in (1, 2, 3)[:max_views]:
            r = await see(vp, None)
            if r.decision == "recognized":
                break
        return single(r)

    top = await see(1, 1)
    if policy == "top-only" or max_views == 1:
        return single(top)
    contenders = top.contenders
    if top.decision == "unknown":
        # Nothing certain from the top; models above the candidate bar are worth a side view.
        # The top view could not rank them, so the margin does not prune here.
        contenders = tuple(
            m
            for m in sorted(top.scores, key=lambda m: (-top.scores[m], m))
            if top.scores[m] > shortlist(m)
        )[:MAX_CONTENDERS]
        if not contenders:
            return single(top)
        skip_top = True
    if policy == "best-next" and top.decision == "recognized":
        assert choice is not None
        if top.model is None:  # recognise() names the model of every "recognized" decision
            raise RuntimeError("the top view was recognised without a model")
        alike = _top_confusers(choice, top.model, float(confusion_limit))
        if not alike:
            return single(top)
        contenders = (top.model, *alike)

    def challengers(m: str) -> list[str]:
        """Models that could still be the object when the top view named ``m``: those above
        the top view's candidate bar (they passed there, but lost by more than the margin)
        and, with a choice, those confused with ``m`` from the top (its confusion table)."""
        near = [b for b in sorted(top.scores, key=lambda b: (-top.scores[b], b))
                if b != m and top.scores[b] > shortlist(b)]  # fmt: skip
        alike = _top_confusers(choice, m, float(confusion_limit)) if choice is not None else ()
        out = [*near, *(b for b in alike if b not in near and b != m)]
        return out[: MAX_CONTENDERS - 1]

    def won_by(rival: str, m: str, side: Recognition, vp: int) -> bool:
        """``rival`` wins side view ``vp`` against ``m``: it passes its own bar there and
        beats ``m``'s score (module docstring)."""
        s = side.scores.get(rival, 0.0)
        return s > bar(rival, vp) and s > side.scores.get(m, 0.0)

    def lookalikes(m: str, side: Recognition, vp: int) -> list[str]:
        """The models verified on this side view that are grey look-alikes of ``m`` at
        ``vp`` (:data:`LOOKALIKE_SHARE`, module docstring): their grey scores there say
        nothing about which of them it is, so a look-alike counts once it verifies at all."""
        if choice is None:
            return []
        table = choice.confusion.get(vp, {})
        return [
            b
            for b in side.scores
            if b != m
            and side.scores.get(b, 0.0) > 0.0
            and min(table.get(m, {}).get(b, 0.0), table.get(b, {}).get(m, 0.0)) > LOOKALIKE_SHARE
        ]

    alike_seen: set[str] = set()  # grey look-alikes of a side view's leader (colour decides)

    def alike_on_sides(m: str) -> list[str]:
        """The grey look-alikes of ``m`` verified on some side view visited so far."""
        out: list[str] = []
        for vp, r in zip(visited, views, strict=True):
            if vp in (2, 3):
                out += [b for b in lookalikes(m, r, vp) if b not in out]
        return out

    def colour_winner(fused: dict[str, float]) -> str | None:
        """The tied model colour singles out (module docstring), or ``None``."""
        best = max(fused.values(), default=0.0)
        tied = [
            m
            for m, v in fused.items()
            if v > 0.0 and (v >= (1.0 - margin) * best or m in alike_seen)
        ]
        if len(tied) < 2:
            return None
        dist = colour_support(index, views, images, tied)
        if len(dist) != len(tied):
            return None  # a tied model has no colour to compare: no tie-break
        ranked = sorted(tied, key=lambda m: (dist[m], m))
        w, runner = ranked[0], ranked[1]
        if dist[w] > COLOUR_MAX or dist[runner] - dist[w] < COLOUR_MARGIN:
            return None
        fused_bar = float(np.mean([bar(w, vp) for vp in visited[(1 if skip_top else 0) :]]))
        side_ok = any(
            vp in (2, 3) and r.scores.get(w, 0.0) > bar(w, vp)
            for vp, r in zip(visited, views, strict=True)
        )
        return w if fused[w] > fused_bar and side_ok else None

    def colour_settled() -> bool:
        """Whether the look may end on look-alikes (module docstring, "Grey look-alikes"):
        colour singles one of them out with the views taken so far, or there is no colour
        tie-break to wait for."""
        return not colour_tiebreak or colour_winner(fused_decision(models)[0]) is not None

    models = list(contenders)
    # A model the top view named on its own (no look-alike passed within the margin) stays
    # named unless a side view is won by another model (module docstring, "Fused score"):
    # the side views are searched against it and its challengers from the top, and a side
    # view where none of them verifies is no evidence. When the top view could not choose,
    # the side view is what decides, so the winner must pass there on its own too.
    named = top.model if top.decision == "recognized" and not skip_top else None
    if named is not None:
        models = [named, *challengers(named)]
    for vp in _side_order(index, tuple(models), choice, smart=policy == "best-next"):
        if len(visited) >= max_views:
            break
        side = await see(vp, vp, models)
        if alike_seen:
            # Look-alikes met on an earlier side view: this one only adds colour evidence
            # (and a side view where the winner passes its own bar) for the tie-break.
            if colour_settled():
                break
            continue
        fused, (decision, model, cont) = fused_decision(models)
        if named is not None:
            own = side.scores.get(named, 0.0)
            rivals = [m for m in models if m != named and won_by(m, named, side, vp)]
            # A look-alike verified beside it: whether or not it passed its own bar here, the
            # grey scores (this view's, and the top view's where they are look-alikes too)
            # cannot say which of them it is.
            twins = lookalikes(named, side, vp) if own > 0.0 else []
            if twins:
                # Grey cannot tell it from a look-alike that verified here too: colour
                # decides among them (module docstring, "Grey look-alikes").
                alike_seen.update([named, *twins])
                models = [named, *twins]
                named = None
                if colour_settled():
                    break
                continue
            if rivals:
                # Overturned: the top view's choice is contradicted; from here the models
                # seen are decided like a top view that could not choose.
                named = None
                models = [top.model, *rivals] if top.model is not None else rivals
                fused, (decision, model, cont) = fused_decision(models)
            elif own > bar(named, vp) or (decision == "recognized" and model == named):
                return result("recognized", named, fused, (named,))
            else:
                continue  # nothing verified against it here: look again, if allowed
        if decision == "recognized" and side.scores.get(model, 0.0) > bar(model, vp):
            twins = lookalikes(model, side, vp)
            if not twins:
                return result(decision, model, fused, cont)
            alike_seen.update([model, *twins])
            models = [model, *twins]
            if colour_settled():
                break
            continue
        if cont:
            # The margin narrows the models to the side view's contenders, but it never
            # drops a grey look-alike of one that verified here ("Grey look-alikes").
            kept = list(cont)
            for m in cont:
                kept += [b for b in lookalikes(m, side, vp) if b not in kept]
            models = kept
    if len(visited) == 1:  # no contender has side views: the top view is all there is
        return single(top)
    fused, (decision, model, cont) = fused_decision(models)
    if named is not None:  # no side view contradicted the top view's choice
        return result("recognized", named, fused, (named,))
    if decision == "recognized":
        # The side check did not confirm the winner on its own view: report the doubt.
        decision, model, cont = "ambiguous", None, cont
    if decision == "ambiguous" and colour_tiebreak:
        # The fused leader's grey look-alikes verified on a side view are tied with it
        # whatever their grey scores ("Grey look-alikes"): colour decides among them.
        lead = max(fused, key=lambda m: (fused[m], m), default=None)
        twins = [] if lead is None else alike_on_sides(lead)
        if lead is not None and twins:
            alike_seen.update([lead, *twins])
            models = [*models, *(b for b in twins if b not in models)]
            fused = fused_decision(models)[0]
        winner = colour_winner(fused)
        if winner is not None:
            return result("recognized", winner, fused, (winner,))
    return result(decision, model, fused, cont)
