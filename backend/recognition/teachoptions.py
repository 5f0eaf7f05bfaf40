"""How a teach is asked for (:class:`TeachOptions`), the object yaws of its rounds and
where a model stands in them (:func:`rounds_guide`); the teach itself is
:mod:`backend.recognition.teach`."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Literal

from vision.errors import InvalidInput

__all__ = ["MAX_ROUNDS", "MAX_WAIT_S", "TOP_ROLLS_RAD", "TeachOptions",
           "rounds_guide", "teach_yaws_rad"]  # fmt: skip

#: Camera rolls (q5 offsets, radians) of the top view: 0 and +-120 deg cover the circle in
#: thirds within q5's +-165.75 deg.  Measured (``benchmarks/teach_yaw.py``, 12 objects at 48
#: random yaws): one roll names 100 % with the object's own score at median 0.39, three
#: rolls 100 % at 0.47 (p10 0.034 -> 0.052): a wider margin above the threshold.
TOP_ROLLS_RAD = (0.0, math.radians(120.0), math.radians(-120.0))
#: Longest a teach waits for an object to arrive after grabbing the background, seconds.
MAX_WAIT_S = 600.0
#: Most teach rounds (object yaws) of one model.
MAX_ROUNDS = 12


def teach_yaws_rad(rounds: int) -> tuple[float, ...]:
    """Object yaws of ``rounds`` teach rounds (the operator or the simulator turns the object
    between rounds, :attr:`TeachOptions.yaw_rad`): ``k * 360 / rounds`` deg, k = 0 ..
    rounds-1, in (-180, 180], spread evenly over the whole turn.

    Other spreads were measured and lost (``benchmarks.recognition_yaw --teach-yaws 4
    --queries 3``, seeds 0, 1 and 2, side ROI and own bars on, 108 trained and 18 untrained
    queries; untrained all unknown in every plan): this plan (0, 90, 180, -90 deg) named
    108; the half turn (0, 45, 90, 135: every round shows the side views a new pair of
    faces, whereas here a 180 deg turn only swaps them) 106; a plan whose top rotations
    (yaw + camera roll, :data:`TOP_ROLLS_RAD`) tile the circle every 30 deg with four
    pairs of side faces (0, 30, -60, 90; ``--teach-yaws-deg``) 106, one of its misses a
    wrong twin.  Both raise the automatic top threshold from 0.107 to 0.131 (the largest
    impostor top score), and the objects they miss scored below it from the top.  With
    3, 6, 9 or 12 rounds this plan repeats the rolls' rotations (0, 120, -120 deg teach the
    top view three rotations thrice); those counts were not measured.

    Raises ``InvalidInput`` unless ``rounds`` is an integer in 1..:data:`MAX_ROUNDS`.
    """
    if isinstance(rounds, bool) or not isinstance(rounds, int) or not 1 <= rounds <= MAX_ROUNDS:
        raise InvalidInput(f"rounds must be an integer in 1..{MAX_ROUNDS}, got {rounds!r}")
    return tuple(math.remainder(2.0 * math.pi * k / rounds, 2.0 * math.pi) for k in range(rounds))


@dataclass(frozen=True)
class TeachOptions:
    """How to teach.

    Attributes
    ----------
    viewpoints : tuple of int, optional
        Viewpoints to take (default: ``(1,)`` for 2d models, ``(1, 2, 3)`` for 3d).
    top_rolls_rad : tuple of float
        Camera rolls of the top view, radians (each within +-pi).
    background : {"grab", "stored"}
        Grab the empty-belt backgrounds first, or use those of an earlier teach.
    object_height_m : float
        Rough height of the object (aims the camera at its top face), metres.
    yaw_rad : float
        The object's yaw relative to its taught pose, when an operator turned it by hand
        for another round of views (stored with the views); :func:`teach_yaws_rad` gives
        the yaws of a given number of rounds (over the whole turn).
    speed : float, optional
        Arm speed fraction (default: the cell's).
    wait_s : float
        With ``background="grab"``: longest wait for the object, seconds.
    replace : bool
        Delete the model's earlier views (in the same transaction as storing the new ones).
    threshold : bool
        Recompute the automatic threshold after storing (default).  ``False`` when more
        rounds of the same teach follow at once (the object turned by hand between rounds):
        the last round recomputes, so the choice is made once over all of them instead of
        after each (it re-runs recognition on every trained view).
    """

    viewpoints: tuple[int, ...] | None = None
    top_rolls_rad: tuple[float, ...] = TOP_ROLLS_RAD
    background: Literal["grab", "stored"] = "grab"
    object_height_m: float = 0.1
    yaw_rad: float = 0.0
    speed: float | None = None
    wait_s: float = 120.0
    replace: bool = False
    threshold: bool = True

    def __post_init__(self) -> None:
        if not isinstance(self.threshold, bool):
            raise InvalidInput(f"threshold must be true or false, got {self.threshold!r}")
        if self.viewpoints is not None:
            vps = tuple(self.viewpoints)
            if (
                not vps
                or len(set(vps)) != len(vps)
                or any(isinstance(v, bool) or v not in (1, 2, 3) for v in vps)
            ):
                raise InvalidInput(f"viewpoints must be distinct values of 1, 2, 3, got {vps!r}")
            object.__setattr__(self, "viewpoints", tuple(sorted(vps)))
        rolls = tuple(float(r) for r in self.top_rolls_rad)
        if not 1 <= len(rolls) <= 12 or not all(
            math.isfinite(r) and abs(r) <= math.pi for r in rolls
        ):
            raise InvalidInput(f"top_rolls_rad must be 1 to 12 angles within +-pi, got {rolls!r}")
        object.__setattr__(self, "top_rolls_rad", rolls)
        if self.background not in ("grab", "stored"):
            raise InvalidInput(f"background must be 'grab' or 'stored', got {self.background!r}")
        h = self.object_height_m
        if isinstance(h, bool) or not (math.isfinite(h) and 0.0 < h <= 0.5):
            raise InvalidInput(f"object_height_m must be in (0, 0.5] m, got {h!r}")
        if not (math.isfinite(self.yaw_rad) and abs(self.yaw_rad) <= math.pi):
            raise InvalidInput(f"yaw_rad must be within +-pi, got {self.yaw_rad!r}")
        if not (math.isfinite(self.wait_s) and 0.0 <= self.wait_s <= MAX_WAIT_S):
            raise InvalidInput(f"wait_s must be in [0, {MAX_WAIT_S:g}] s, got {self.wait_s!r}")
        if self.speed is not None and not (math.isfinite(self.speed) and 0.0 < self.speed <= 1.0):
            raise InvalidInput(f"speed must be in (0, 1], got {self.speed!r}")


def rounds_guide(taught: int, recommended: int) -> dict[str, Any]:
    """Where a model stands in its teach rounds (:data:`~backend.recognition.thresholds.
    RECOMMENDED_ROUNDS` for its kind), for the wizard and the CLI: ``taught``,
    ``recommended``, and while rounds remain ``next_round`` (1-based) and ``next_yaw_deg``,
    the yaw to turn the object to, from its first round's pose (:func:`teach_yaws_rad`)."""
    out: dict[str, Any] = {"taught": taught, "recommended": recommended,
                           "next_round": None, "next_yaw_deg": None}  # fmt: skip
    if taught < recommended:
        out["next_round"] = taught + 1
        out["next_yaw_deg"] = round(math.degrees(teach_yaws_rad(recommended)[taught]), 1)
    return out
