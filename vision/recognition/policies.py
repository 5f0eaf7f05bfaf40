"""The viewpoint policies of 3D recognition as small objects over one shared state.

:func:`vision.recognition.recognise_views` validates its arguments, builds a
:class:`~vision.recognition.viewstate.ViewState` (the views taken so far, the thresholds
of each viewpoint, the models still in play) and hands it to the :class:`Policy` named by
``policy``. The rules the policies share (the fused score, own bars, grey look-alikes, the
colour tie-break) are described in the docstring of :mod:`vision.recognition.views`.

- :class:`Naive` (Figure 6 of the chapter): every view against every trained view.
- :class:`TopOnly`: the top view alone (section 3.5.1).
- :class:`TwoViews` (section 3.5.3): the top view, checked or decided by side views.
- :class:`BestNext`: :class:`TwoViews` that accepts an unconfused top view at once and
  visits the least confused side viewpoint first.
"""

from __future__ import annotations

from collections.abc import Mapping
from types import MappingProxyType
from typing import Protocol

from vision.recognition.recognise import Recognition
from vision.recognition.viewstate import (
    MAX_CONTENDERS,
    SIDES,
    ViewsRecognition,
    ViewState,
    top_confusers,
)

__all__ = [
    "POLICY_OBJECTS",
    "BestNext",
    "Naive",
    "Policy",
    "TopOnly",
    "TwoViews",
]


class Policy(Protocol):
    """A viewpoint policy: which views to take and what to answer after them."""

    #: The name ``recognise_views`` knows it by.
    name: str
    #: Whether it needs a :class:`ThresholdChoice` (its confusion table).
    needs_choice: bool

    async def run(self, state: ViewState) -> ViewsRecognition:
        """Take the views and answer.

        Parameters
        ----------
        state : ViewState
            A fresh state; the policy takes views through :meth:`ViewState.see`.

        Returns
        -------
        ViewsRecognition
        """
        ...


class Naive:
    """Figure 6: every view against every trained view of every viewpoint; stop at the
    first view where exactly one model is recognised, after ``max_views`` at most."""

    name = "naive"
    needs_choice = False

    async def run(self, state: ViewState) -> ViewsRecognition:
        """Look from viewpoints 1, 2, 3 in turn until one view recognises a model."""
        for vp in (1, 2, 3)[: state.max_views]:
            r = await state.see(vp, None)
            if r.decision == "recognized":
                break
        return state.single(r)


class TopOnly:
    """The 2D algorithm of section 3.5.1 on the top view alone."""

    name = "top-only"
    needs_choice = False

    async def run(self, state: ViewState) -> ViewsRecognition:
        """Answer what the top view answers."""
        return state.single(await state.see(1, 1))


class TwoViews:
    """Section 3.5.3: the top view against every model's top views, then side views
    that check the model it named or decide among its contenders."""

    name = "two-views"
    needs_choice = False

    def accepts_top(self, state: ViewState, top: Recognition) -> bool:
        """Whether a top view that recognised a model is the answer without a side view."""
        return False

    def side_order(self, state: ViewState, models: tuple[str, ...]) -> list[int]:
        """Side viewpoints where one of ``models`` has trained views, in the order visited."""
        return [vp for vp in SIDES if any(vp in state.index.viewpoints_of(m) for m in models)]

    async def run(self, state: ViewState) -> ViewsRecognition:
        """The top view, then side views until one decides or ``max_views`` are taken."""
        top = await state.see(1, 1)
        if state.max_views == 1:
            return state.single(top)
        contenders = top.contenders
        if top.decision == "unknown":
            # Nothing certain from the top; models above their shortlist bar are worth a
            # side view. The top view could not rank them, so the margin does not prune here.
            contenders = tuple(
                m
                for m in sorted(top.scores, key=lambda m: (-top.scores[m], m))
                if top.scores[m] > state.shortlist(m)
            )[:MAX_CONTENDERS]
            if not contenders:
                return state.single(top)
            state.skip_top = True
        if top.decision == "recognized" and self.accepts_top(state, top):
            return state.single(top)
        state.models = list(contenders)
        # A model the top view named on its own stays named unless a side view is won by
        # another model ("Fused score"): the side views are searched against it and its
        # challengers from the top, and a side view where none of them verifies is no
        # evidence. When the top view could not choose, the side view decides, so the
        # winner must pass there on its own too.
        if top.decision == "recognized":
            assert top.model is not None  # recognise() names every recognised model
            state.named = top.model
            state.models = [top.model, *state.challengers(top.model)]
        for vp in self.side_order(state, tuple(state.models)):
            if len(state.visited) >= state.max_views:
                break
            step = await self._side_view(state, vp)
            if isinstance(step, ViewsRecognition):
                return step
            if step:
                break
        return self._after_sides(state)

    async def _side_view(self, state: ViewState, vp: int) -> ViewsRecognition | bool:
        """Take side view ``vp``; returns the answer, ``True`` when the look ends without
        one yet, ``False`` to look again (if allowed)."""
        side = await state.see(vp, vp, state.models)
        if state.alike_seen:
            # Look-alikes met on an earlier side view: this one only adds colour evidence
            # (and a side view where the winner passes its own bar) for the tie-break.
            return state.colour_settled()
        fused, (decision, model, cont) = state.fused_decision(state.models)
        named = state.named
        if named is not None:
            own = side.scores.get(named, 0.0)
            rivals = [m for m in state.models if m != named and state.won_by(m, named, side, vp)]
            # A look-alike verified beside it: whether or not it passed its own bar here,
            # the grey scores cannot say which of them it is; colour decides among them.
            twins = state.lookalikes(named, side, vp) if own > 0.0 else []
            if twins:
                state.named = None
                return state.to_colour([named, *twins])
            if rivals:
                # Overturned: the top view's choice is contradicted; from here the models
                # seen are decided like a top view that could not choose.
                state.named = None
                state.models = [named, *rivals]
                fused, (decision, model, cont) = state.fused_decision(state.models)
            elif own > state.bar(named, vp) or (decision == "recognized" and model == named):
                return state.result("recognized", named, fused, (named,))
            else:
                return False  # nothing verified against it here
        # (A recognised decision always names its model; the test tells the type checker.)
        if (
            decision == "recognized"
            and model is not None
            and side.scores.get(model, 0.0) > state.bar(model, vp)
        ):
            twins = state.lookalikes(model, side, vp)
            if not twins:
                return state.result(decision, model, fused, cont)
            return state.to_colour([model, *twins])
        if cont:
            # The margin narrows the models to the side view's contenders, but it never
            # drops a grey look-alike of one that verified here ("Grey look-alikes").
            kept = list(cont)
            for m in cont:
                kept += [b for b in state.lookalikes(m, side, vp) if b not in kept]
            state.models = kept
        return False

    def _after_sides(self, state: ViewState) -> ViewsRecognition:
        """The answer once the side views end without one."""
        if len(state.visited) == 1:  # no contender has side views: the top view is all
            return state.single(state.top)
        fused, (decision, model, cont) = state.fused_decision(state.models)
        if state.named is not None:  # no side view contradicted the top view's choice
            return state.result("recognized", state.named, fused, (state.named,))
        if decision == "recognized":
            # The side check did not confirm the winner on its own view: report the doubt.
            decision, model = "ambiguous", None
        if decision == "ambiguous" and state.colour_tiebreak:
            # The fused leader's grey look-alikes verified on a side view are tied with it
            # whatever their grey scores ("Grey look-alikes"): colour decides among them.
            lead = max(fused, key=lambda m: (fused[m], m), default=None)
            twins = [] if lead is None else state.alike_on_sides(lead)
            if lead is not None and twins:
                state.alike_seen.update([lead, *twins])
                state.models = [*state.models, *(b for b in twins if b not in state.models)]
                fused = state.fused_decision(state.models)[0]
            winner = state.colour_winner(fused)
            if winner is not None:
                return state.result("recognized", winner, fused, (winner,))
        return state.result(decision, model, fused, cont)


class BestNext(TwoViews):
    """:class:`TwoViews` that accepts a top view no other model is confused with (the
    confusion table, below ``confusion_limit``) and visits the side viewpoint where the
    models in play are least confused first."""

    name = "best-next"
    needs_choice = True

    def accepts_top(self, state: ViewState, top: Recognition) -> bool:
        """Whether no other model is confused with the recognised one from the top."""
        choice = state.choice
        assert choice is not None and top.model is not None  # needs_choice; recognised
        return not top_confusers(choice, top.model, state.confusion_limit)

    def side_order(self, state: ViewState, models: tuple[str, ...]) -> list[int]:
        """:meth:`TwoViews.side_order` sorted by the summed pairwise confusion of
        ``models`` at each viewpoint, least first."""
        sides = super().side_order(state, models)
        choice = state.choice
        if choice is None:
            return sides

        def cost(vp: int) -> float:
            table = choice.confusion.get(vp, {})
            return sum(table.get(a, {}).get(b, 0.0) for a in models for b in models if a != b)

        return sorted(sides, key=lambda vp: (cost(vp), vp))


#: The policies by name, in the order of :data:`vision.recognition.POLICIES`.
POLICY_OBJECTS: Mapping[str, Policy] = MappingProxyType(
    {p.name: p for p in (Naive(), TopOnly(), TwoViews(), BestNext())}
)
