"""The state the viewpoint policies share during one :func:`recognise_views` call.

:class:`ViewState` holds the validated arguments, the views taken so far and the models
still in play, and the steps every policy is made of: taking a view, each model's bar at a
viewpoint, the fused decision, the challengers of a named model, grey look-alikes and the
colour tie-break (the rules are described in the docstring of
:mod:`vision.recognition.views`). :mod:`vision.recognition.policies` decides with them.
"""

from __future__ import annotations

import asyncio
import inspect
from collections.abc import Awaitable, Callable, Mapping, Sequence
from dataclasses import dataclass, field
from types import MappingProxyType

import numpy as np

from vision.features import Features
from vision.recognition.index import ViewIndex
from vision.recognition.recognise import Recognition, decide_with, resolve_threshold, search_of
from vision.recognition.threshold import ThresholdChoice

__all__ = [
    "COLOUR_MARGIN",
    "COLOUR_MAX",
    "LOOKALIKE_SHARE",
    "MAX_CONTENDERS",
    "SIDES",
    "Look",
    "LookResult",
    "ViewState",
    "ViewsRecognition",
    "take_look",
    "top_confusers",
]

#: Side views are checked against at most this many contenders from an inconclusive top view.
MAX_CONTENDERS = 8

#: Two models are grey look-alikes at a side viewpoint when each passes the viewpoint's
#: candidate bar on more than half of the other's held-out views there (the confusion table
#: of :func:`choose_threshold`): more often than not the grey features cannot tell them
#: apart, so their grey scores there never decide between them ("Grey look-alikes").
LOOKALIKE_SHARE = 0.5

#: Colour tie-break (module docstring of :mod:`vision.recognition.views`), in the log units
#: of ``colour_distance``: every other tied model must be at least ``COLOUR_MARGIN`` farther
#: than the winner (0.7: about twice or half the share of one hue), and the winner at most
#: ``COLOUR_MAX`` from its own views: a twin's own side views lie far closer than its
#: red-band twin's (the band is a few per cent of the side view), while strongly coloured
#: parts whose colour shifts between views (the red valve block) are never decided by colour.
COLOUR_MARGIN = 0.7
COLOUR_MAX = 2.0

SIDES = (2, 3)

LookResult = np.ndarray | Features | tuple[np.ndarray, np.ndarray | None]
Look = Callable[[int], LookResult | Awaitable[LookResult]]
#: ``(index, views, images, models) -> {model: colour distance}``
ColourSupport = Callable[
    [ViewIndex, list[Recognition], list[np.ndarray | None], list[str]], dict[str, float]
]
#: ``(decision, model, contenders)`` of :func:`vision.recognition.recognise.decide_with`.
Decision = tuple[str, str | None, tuple[str, ...]]


@dataclass(frozen=True, eq=False)
class ViewsRecognition:
    """Result of :func:`vision.recognition.recognise_views`.

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


async def take_look(look: Look, viewpoint: int) -> tuple[np.ndarray | Features, np.ndarray | None]:
    """Ask ``look`` for what the camera sees from ``viewpoint``.

    Parameters
    ----------
    look : callable(viewpoint) -> image, (image, mask) or Features; sync or async
    viewpoint : int
        1 (top), 2 or 3 (sides).

    Returns
    -------
    image : ndarray of shape (H, W[, 3]) or Features
    mask : ndarray of shape (H, W) or None

    Raises
    ------
    ValueError
        ``look`` answered something other than an image, ``(image, mask)`` or features.
    """
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


def top_confusers(choice: ThresholdChoice, model: str, limit: float) -> tuple[str, ...]:
    """Models confused with ``model`` from the top, either way.

    Parameters
    ----------
    choice : ThresholdChoice
        Holds the confusion table of :func:`choose_threshold` (``confusion[1]`` for the top).
    model : str
    limit : float
        Share in [0, 1] of held-out views on which a model passes for another to count.

    Returns
    -------
    tuple of str
        The confused models, sorted by name.
    """
    row = choice.confusion.get(1, {}).get(model, {})
    rows_in = {a: r.get(model, 0.0) for a, r in choice.confusion.get(1, {}).items() if a != model}
    alike = {b for b, c in row.items() if c >= limit} | {
        a for a, c in rows_in.items() if c >= limit
    }
    return tuple(sorted(alike))


@dataclass(eq=False)
class ViewState:
    """What the policies share during one :func:`recognise_views` call: its (validated)
    arguments, the views taken so far, and the models still in play.

    Attributes
    ----------
    look, index, policy, max_views, threshold, margin, confusion_limit, colour_tiebreak
        The arguments of :func:`recognise_views`.
    recognise : callable
        :func:`vision.recognition.recognise`, run in a worker thread for each view.
    colour_support : callable
        :func:`vision.recognition.views.colour_support`, for the colour tie-break.
    visited : list of int
        Viewpoints visited, in order.
    views : list of Recognition
        The recognition of each visited view, aligned with ``visited``.
    images : list of ndarray or None
        The RGB image of each visited view (``None`` for grey images and features).
    skip_top : bool
        The top view only shortlisted models (it could not rank them), so the fused score
        leaves it out once a side view is taken.
    models : list of str
        The models the next side view is searched against.
    named : str or None
        The model the top view named on its own, while no side view has contradicted it.
    alike_seen : set of str
        Grey look-alikes met on a side view: colour decides among them.
    """

    look: Look
    index: ViewIndex
    policy: str
    max_views: int
    threshold: float | ThresholdChoice | None
    margin: float
    confusion_limit: float
    colour_tiebreak: bool
    recognise: Callable[..., Recognition]
    colour_support: ColourSupport
    visited: list[int] = field(default_factory=list)
    views: list[Recognition] = field(default_factory=list)
    images: list[np.ndarray | None] = field(default_factory=list)
    skip_top: bool = False
    models: list[str] = field(default_factory=list)
    named: str | None = None
    alike_seen: set[str] = field(default_factory=set)

    @property
    def choice(self) -> ThresholdChoice | None:
        """The threshold choice, when one was given."""
        return self.threshold if isinstance(self.threshold, ThresholdChoice) else None

    @property
    def top(self) -> Recognition:
        """The recognition of the top view (the first view taken)."""
        return self.views[0]

    def at(self, vp: int) -> float | ThresholdChoice | None:
        """The threshold a view from ``vp`` is recognised with."""
        choice = self.choice
        return choice.at(vp) if choice is not None else self.threshold

    def bar(self, model: str, vp: int) -> float:
        """``model``'s bar at ``vp``: its own bar on a side view ("Own bars"), its
        acceptance threshold on the top view."""
        choice = self.choice
        if choice is not None and vp in SIDES:
            return choice.own(model, vp)
        glob, per_model = resolve_threshold(self.at(vp))
        return per_model.get(model, glob)

    def shortlist(self, model: str) -> float:
        """Bar above which a top-view score makes ``model`` worth a side view."""
        choice = self.choice
        if choice is None:
            return self.bar(model, 1)
        return min(choice.at(1).candidate, choice.own(model, 1))

    async def see(
        self, vp: int, viewpoint: int | None, models: Sequence[str] | None = None
    ) -> Recognition:
        """Look from ``vp`` and recognise the view; the view is appended to the state.

        Parameters
        ----------
        vp : int
            Viewpoint the camera looks from (1, 2 or 3); its threshold is used.
        viewpoint : int or None
            Viewpoint whose trained views are searched (``None``: every viewpoint, as the
            naive policy does).
        models : sequence of str, optional
            Restrict the search to these models.

        Returns
        -------
        Recognition
        """
        image, mask = await take_look(self.look, vp)
        r = await asyncio.to_thread(
            self.recognise,
            self.index,
            image,
            viewpoint=viewpoint,
            mask=mask,
            threshold=self.at(vp),
            margin=self.margin,
            models=models,
            search=None if viewpoint is None else search_of(viewpoint),
        )
        self.visited.append(vp)
        self.views.append(r)
        self.images.append(image if isinstance(image, np.ndarray) and image.ndim == 3 else None)
        return r

    def fused_decision(self, models: list[str]) -> tuple[dict[str, float], Decision]:
        """The fused score of ``models`` and the decision on it ("Fused score").

        Each model's score is the mean of its scores over the views that count (every view
        taken, less the top view when it only shortlisted), its bar the mean of its bars
        there; the decision rule of section 3.5.1 is applied to them.

        Returns
        -------
        fused : dict of str to float
        decision : tuple
            ``(decision, model, contenders)`` as from :func:`decide_with`.
        """
        first = 1 if self.skip_top and len(self.views) > 1 else 0
        views = self.views[first:]
        fused = {m: float(np.mean([r.scores.get(m, 0.0) for r in views])) for m in models}
        bars = {m: float(np.mean([self.bar(m, vp) for vp in self.visited[first:]])) for m in models}
        return fused, decide_with(fused, 1.0, bars, margin=self.margin)

    def result(
        self,
        decision: str,
        model: str | None,
        scores: Mapping[str, float],
        contenders: Sequence[str],
    ) -> ViewsRecognition:
        """The answer, with the views taken so far.

        Parameters
        ----------
        decision : {"recognized", "ambiguous", "unknown"}
        model : str or None
            The recognised model; its score is the answer's score (else the best score).
        scores : mapping of str to float
        contenders : sequence of str

        Returns
        -------
        ViewsRecognition
        """
        best = max(scores.values(), default=0.0)
        return ViewsRecognition(
            decision=decision,
            model=model,
            score=float(scores[model]) if model is not None else float(best),
            scores=MappingProxyType(dict(scores)),
            contenders=tuple(contenders),
            policy=self.policy,
            viewpoints=tuple(self.visited),
            views=tuple(self.views),
        )

    def single(self, r: Recognition) -> ViewsRecognition:
        """The answer of one view ``r`` taken as it is."""
        return self.result(r.decision, r.model, dict(r.scores), r.contenders)

    def challengers(self, m: str) -> list[str]:
        """Models that could still be the object when the top view named ``m``: those above
        their shortlist bar from the top (they passed there, but lost by more than the
        margin) and, with a choice, those confused with ``m`` from the top."""
        top = self.top
        near = [b for b in sorted(top.scores, key=lambda b: (-top.scores[b], b))
                if b != m and top.scores[b] > self.shortlist(b)]  # fmt: skip
        choice = self.choice
        alike = top_confusers(choice, m, self.confusion_limit) if choice is not None else ()
        out = [*near, *(b for b in alike if b not in near and b != m)]
        return out[: MAX_CONTENDERS - 1]

    def won_by(self, rival: str, m: str, side: Recognition, vp: int) -> bool:
        """``rival`` wins side view ``vp`` against ``m``: it passes its own bar there and
        beats ``m``'s score."""
        s = side.scores.get(rival, 0.0)
        return s > self.bar(rival, vp) and s > side.scores.get(m, 0.0)

    def lookalikes(self, m: str, side: Recognition, vp: int) -> list[str]:
        """The models verified on this side view that are grey look-alikes of ``m`` at
        ``vp`` (:data:`LOOKALIKE_SHARE`): their grey scores there say nothing about which
        of them it is, so a look-alike counts once it verifies at all."""
        choice = self.choice
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

    def alike_on_sides(self, m: str) -> list[str]:
        """The grey look-alikes of ``m`` verified on some side view visited so far."""
        out: list[str] = []
        for vp, r in zip(self.visited, self.views, strict=True):
            if vp in SIDES:
                out += [b for b in self.lookalikes(m, r, vp) if b not in out]
        return out

    def colour_winner(self, fused: dict[str, float]) -> str | None:
        """The tied model colour singles out ("Colour tie-break"), or ``None``."""
        best = max(fused.values(), default=0.0)
        tied = [
            m
            for m, v in fused.items()
            if v > 0.0 and (v >= (1.0 - self.margin) * best or m in self.alike_seen)
        ]
        if len(tied) < 2:
            return None
        dist = self.colour_support(self.index, self.views, self.images, tied)
        if len(dist) != len(tied):
            return None  # a tied model has no colour to compare: no tie-break
        ranked = sorted(tied, key=lambda m: (dist[m], m))
        w, runner = ranked[0], ranked[1]
        if dist[w] > COLOUR_MAX or dist[runner] - dist[w] < COLOUR_MARGIN:
            return None
        counted = self.visited[(1 if self.skip_top else 0) :]
        fused_bar = float(np.mean([self.bar(w, vp) for vp in counted]))
        side_ok = any(
            vp in SIDES and r.scores.get(w, 0.0) > self.bar(w, vp)
            for vp, r in zip(self.visited, self.views, strict=True)
        )
        return w if fused[w] > fused_bar and side_ok else None

    def colour_settled(self) -> bool:
        """Whether the look may end on look-alikes ("Grey look-alikes"): colour singles
        one of them out with the views taken so far, or there is no tie-break to wait for."""
        if not self.colour_tiebreak:
            return True
        return self.colour_winner(self.fused_decision(self.models)[0]) is not None

    def to_colour(self, models: list[str]) -> bool:
        """Send ``models``, grey look-alikes on a side view, to the colour tie-break; returns
        whether the look may end here (:meth:`colour_settled`)."""
        self.alike_seen.update(models)
        self.models = list(models)
        return self.colour_settled()
