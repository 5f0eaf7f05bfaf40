"""3D recognition over viewpoints (chapter sections 3.5.2 and 3.5.3, Figures 6 and 7).

``recognise_views(look, index, policy=...)`` asks the caller for images, ``look(viewpoint)``,
and decides after one, two or three of them. Each policy is a small object
(:mod:`vision.recognition.policies`) over one shared state
(:mod:`vision.recognition.viewstate`); this module validates the arguments, builds the
state and hands it to the policy named. ``look`` may be a plain function or a coroutine
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

    A model named by the top view alone is not put to the fused score. Its top score passed
    a bar set above the impostor scores of the top views (the conformal rule of
    :func:`choose_threshold`; with fewer than 199 impostor scores at the default 1 % target
    it is the largest score any other model's top view got), so the top view already bounds
    how often an untrained object is named; what the side views add is the chapter's check
    against look-alikes. A side view where neither it nor a challenger verifies (the object
    seen at a yaw whose side was never taught verifies little) is no evidence either way,
    whereas fused as 0 it would drag a clear top score under the mean bar. So: the model is
    confirmed by a side view where it passes its bar (or the fused decision names it); it is
    *overturned* by a side view won by a challenger (the challenger passes its own side bar
    there and beats the model's score), after which the models seen are decided as after an
    ambiguous top view (the fused decision, a winner passing its own side bar, else
    ``ambiguous`` and the colour tie-break); if no side view does either, it stays named.
    Untrained objects stay guarded where the top view did not name one model alone (only
    shortlisted, or look-alikes within the margin such as the twin wheels): there the side
    views decide.

Own bars
    On a side view a model's bar is its own bar there (``ThresholdChoice.own``: from the
    scores it gave the other models' views, never below the pooled rule, at most the
    viewpoint's bar; :func:`choose_threshold`, "Own bars"), not the viewpoint's global bar:
    that one is set by the model most prone to verify others (a wheel's), and plain parts
    that verify with few inliers would never pass it. The fused bar
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
    there only below its own bar, which the tie-break requires on some side view. For the
    same reason
    the ambiguity margin, which narrows the models checked on the next side view to the
    contenders, keeps a look-alike of a contender that verified on this one, and when the
    side views end without a decision the fused leader's look-alikes verified on any side
    view are tied with it for colour, however far below it their grey scores fell (else,
    once the margin has dropped the true twin, it is never compared by colour).

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

import numpy as np

from vision.recognition.colour import colour_distance, held_sectors
from vision.recognition.index import ViewIndex, view_colour
from vision.recognition.policies import POLICY_OBJECTS
from vision.recognition.recognise import DEFAULT_MARGIN, Recognition, decide, recognise
from vision.recognition.threshold import ThresholdChoice
from vision.recognition.viewstate import (
    COLOUR_MARGIN,
    COLOUR_MAX,
    LOOKALIKE_SHARE,
    MAX_CONTENDERS,
    Look,
    LookResult,
    ViewsRecognition,
    ViewState,
)

__all__ = [
    "COLOUR_MARGIN",
    "COLOUR_MAX",
    "DEFAULT_CONFUSION_LIMIT",
    "LOOKALIKE_SHARE",
    "MAX_CONTENDERS",
    "POLICIES",
    "Look",
    "LookResult",
    "ViewsRecognition",
    "colour_support",
    "recognise_views",
]

#: The policy names, in the order the module docstring describes them.
POLICIES = tuple(POLICY_OBJECTS)
#: ``best-next`` accepts a top-view recognition when every other model passes on less than
#: this share of the model's held-out top views.
DEFAULT_CONFUSION_LIMIT = 0.05


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
    if POLICY_OBJECTS[policy].needs_choice and not isinstance(threshold, ThresholdChoice):
        raise ValueError(f"policy {policy!r} needs threshold=ThresholdChoice (its confusion table)")
    if (
        isinstance(confusion_limit, bool)
        or not isinstance(confusion_limit, int | float)
        or not 0.0 <= float(confusion_limit) <= 1.0
    ):
        raise ValueError(f"confusion_limit must be in [0, 1], got {confusion_limit!r}")
    if not isinstance(colour_tiebreak, bool):
        raise ValueError(f"colour_tiebreak must be true or false, got {colour_tiebreak!r}")
    decide({}, threshold=threshold, margin=margin)  # validates threshold and margin before moving
    state = ViewState(
        look=look,
        index=index,
        policy=policy,
        max_views=max_views,
        threshold=threshold,
        margin=margin,
        confusion_limit=float(confusion_limit),
        colour_tiebreak=colour_tiebreak,
        # This module's names, read at call time: replacing them scripts the views' answers.
        recognise=recognise,
        colour_support=colour_support,
    )
    return await POLICY_OBJECTS[policy].run(state)
