"""Closed-form inverse kinematics of the ASEA arm (chapter eq. 20 solved for the joints).

The pose is the chapter's ``(x, y, z, u, w)`` plus the roll about the approach axis.  It
names one physical flange pose: the position ``p = (x, y, z)`` and the approach axis

    a = (u cos(theta), u sin(theta), w),    theta = atan2(y, x),

i.e. ``(u, w)`` are the approach direction's components in the vertical plane through the
base z axis and ``p``, ``u`` counted radially outwards.  With ``phi = atan2(w, u)`` and the
roll ``psi`` the flange orientation is ``R_base_ee = Rz(theta) Ry(pi/2 - phi) Rz(psi)``, the
convention of :mod:`robot.kinematics.forward`.

Solving eq. 20 (``r`` is the signed distance along the arm plane, ``L45 = L4 + L5``):

* front branches: ``q1 = theta``, ``r = +hypot(x, y)``, arm-plane angle ``phi``, ``q5 = psi``;
* reach-over branches: ``q1 = theta + pi``, ``r = -hypot(x, y)``, arm-plane angle
  ``pi - phi`` (the arm plane is turned round, so the approach angle measured in it flips),
  ``q5 = psi + pi`` (``Rz(pi) Ry(phi - pi/2) = Ry(pi/2 - phi) Rz(pi)``), which gives the same
  ``T_base_ee``; eq. 20 then reports ``u`` with the opposite sign, its ``u`` being measured
  along the arm's own plane;
* wrist centre in the arm plane: ``rw = r - L45 cos(phi_b)``, ``zw = z - L1 - L45 sin(phi_b)``;
* two-link arm L2, L3: ``cos q3 = (rw^2 + zw^2 - L2^2 - L3^2) / (2 L2 L3)``, ``q3 = -/+ acos``
  (elbow up / elbow down), ``q2 = atan2(zw, rw) - atan2(L3 sin q3, L2 + L3 cos q3)``;
* ``q4 = phi_b - q2 - q3``.

Each angle is then brought into its joint range by multiples of 2 pi (for q1, whose range
spans a full turn, the representative nearest the seed).  "Elbow up" is ``q3 < 0``, the
posture of a forward reach in which the forearm folds down from the upper arm; the ASEA
ranges (q3 in [-126, -63] deg) allow only that one, and the reach-over branches, which need
the wrist behind the column, are never within the ASEA ranges: they are still returned by
:func:`ik_solutions` with the joint that blocks them.

When the target lies on the q1 axis (``x = y = 0``), ``theta`` is free: the seed's q1 is used.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from robot.errors import JointLimitsBlock, OutOfReach
from robot.model import ASEA, ArmModel

__all__ = [
    "BRANCHES",
    "MAX_ABS_POSITION_M",
    "MAX_ABS_ROLL_RAD",
    "UNIT_TOL",
    "IKSolution",
    "arm_constants",
    "check_pose",
    "ik",
    "ik_solutions",
    "pose_from_flange",
]

TAU = 2.0 * math.pi
#: Tolerance on the joint ranges, radians (the same as :func:`robot.model.check_joints`).
LIMIT_TOL = 1e-9
#: ``|hypot(u, w) - 1|`` above this is refused as not a direction.
UNIT_TOL = 1e-6
#: Largest |x|, |y|, |z| of a target, metres: the arm reaches about 1.5 m, so anything past
#: this is a unit mistake (millimetres sent as metres), refused rather than solved.
MAX_ABS_POSITION_M = 5.0
#: Largest |roll| about the approach axis, radians (two turns either way; it wraps into q5).
MAX_ABS_ROLL_RAD = 4.0 * math.pi
#: ``|cos q3|`` may exceed 1 by this much (rounding at full stretch) before "out of reach".
_REACH_EPS = 1e-12
#: Below this horizontal distance, metres, the target is on the q1 axis.
_AXIS_EPS = 1e-12
#: Branch names in the order every function returns them.
BRANCHES = ("front-elbow-up", "front-elbow-down", "over-elbow-up", "over-elbow-down")


@dataclass(frozen=True)
class ArmConstants:
    """Floats of an :class:`ArmModel` unpacked once for the scalar solver (internal)."""

    model: ArmModel
    L1: float
    L2: float
    L3: float
    L45: float
    lo: tuple[float, ...]  # lower limits minus LIMIT_TOL
    hi: tuple[float, ...]  # upper limits plus LIMIT_TOL
    full_turn: tuple[bool, ...]  # range spans 2 pi: two representatives may be in range
    q_home: tuple[float, ...]


_CACHE: dict[int, ArmConstants] = {}


def arm_constants(model: ArmModel) -> ArmConstants:
    """Return the cached float constants of ``model`` (kept alive with the cache entry)."""
    c = _CACHE.get(id(model))
    if c is not None and c.model is model:
        return c
    lo = tuple(float(v) - LIMIT_TOL for v in model.lower)
    hi = tuple(float(v) + LIMIT_TOL for v in model.upper)
    c = ArmConstants(
        model=model,
        L1=float(model.L1),
        L2=float(model.L2),
        L3=float(model.L3),
        L45=float(model.L45),
        lo=lo,
        hi=hi,
        full_turn=tuple(h - lo_ >= TAU for lo_, h in zip(lo, hi, strict=True)),
        q_home=tuple(float(v) for v in model.q_home),
    )
    _CACHE[id(model)] = c
    return c


@dataclass(frozen=True)
class IKSolution:
    """One branch of the inverse kinematics.

    Attributes
    ----------
    q : ndarray of shape (5,)
        Joint values, radians.  Each angle is the 2 pi representative inside its range
        (nearest the seed if two are), or, when none is, its principal value in (-pi, pi].
    branch : str
        One of :data:`BRANCHES`.
    within_limits : bool
        True when every joint lies within its range.
    violated_joints : tuple of int
        1-based numbers of the joints outside their ranges (empty when within limits).
    detail : str
        Empty when within limits, else which joint values lie outside which ranges.
    """

    q: NDArray[np.float64]
    branch: str
    within_limits: bool
    violated_joints: tuple[int, ...]
    detail: str

    def as_dict(self) -> dict[str, object]:
        """JSON-friendly form for ``POST /api/kinematics/ik``."""
        return {
            "joints": [float(v) for v in self.q],
            "within_limits": self.within_limits,
            "branch": self.branch,
            "violated_joints": list(self.violated_joints),
            "detail": self.detail,
        }


# -- input checks -----------------------------------------------------------------------------
def check_pose(pose: Sequence[float] | ArrayLike) -> tuple[float, float, float, float, float]:
    """Validate a chapter pose ``(x, y, z, u, w)`` and return it as five floats.

    Raises ``ValueError`` (quoting the pose) unless it holds five finite numbers (not
    booleans) with ``|x|, |y|, |z| <= MAX_ABS_POSITION_M`` and ``|hypot(u, w) - 1| <= UNIT_TOL``.
    """
    if isinstance(pose, np.ndarray):
        pose = pose.tolist()
    try:
        x, y, z, u, w = pose  # type: ignore[misc,str-unpack]
        if any(isinstance(v, bool | np.bool_) for v in (x, y, z, u, w)):
            raise TypeError
        x, y, z, u, w = float(x), float(y), float(z), float(u), float(w)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        raise ValueError(f"pose must be five numbers (x, y, z, u, w), got {pose!r}") from None
    if not all(abs(v) <= MAX_ABS_POSITION_M for v in (x, y, z)):
        raise ValueError(
            f"pose position must be finite and within {MAX_ABS_POSITION_M:g} m of the base on "
            f"each axis, got (x, y, z) = ({x!r}, {y!r}, {z!r})"
        )
    n = math.hypot(u, w)
    if not (abs(n - 1.0) <= UNIT_TOL) or not math.isfinite(x + y + z):
        raise ValueError(
            "pose must hold a finite position and a unit approach direction "
            f"(u = cos(q2+q3+q4), w = sin(q2+q3+q4), u^2 + w^2 = 1 within {UNIT_TOL:g}); "
            f"got (x, y, z, u, w) = ({x!r}, {y!r}, {z!r}, {u!r}, {w!r}), |(u, w)| = {n!r}"
        )
    return x, y, z, u, w


def _unpack_seed(seed: ArrayLike | None, c: ArmConstants) -> tuple[float, ...]:
    if seed is None:
        return c.q_home
    try:
        vals = seed.tolist() if isinstance(seed, np.ndarray) else list(seed)  # type: ignore[arg-type]
        if len(vals) != 5:
            raise ValueError
        s = (float(vals[0]), float(vals[1]), float(vals[2]), float(vals[3]), float(vals[4]))  # type: ignore[arg-type]
    except (TypeError, ValueError):
        raise ValueError(f"seed must be 5 finite joint values (radians), got {seed!r}") from None
    if not all(map(math.isfinite, s)):
        raise ValueError(f"seed must be 5 finite joint values (radians), got {seed!r}")
    return s


def _check_roll(roll: float) -> float:
    if isinstance(roll, bool | np.bool_):
        raise ValueError(f"roll must be an angle in radians, not a boolean, got {roll!r}")
    r = float(roll)
    if not (abs(r) <= MAX_ABS_ROLL_RAD):
        raise ValueError(
            f"roll must be a finite angle within +-{MAX_ABS_ROLL_RAD:.6g} rad (two turns), "
            f"got {roll!r}"
        )
    return r


# -- the closed form ----------------------------------------------------------------------------
def _raw_branches(
    c: ArmConstants, x: float, y: float, z: float, u: float, w: float, roll: float, seed_q1: float
) -> tuple[tuple[float, float, float, float, float], ...] | float:
    """The four branches before range fitting, or the wrist distance when out of reach."""
    rho = math.hypot(x, y)
    theta = math.atan2(y, x) if rho > _AXIS_EPS else seed_q1
    n = math.hypot(u, w)
    cu, sw = u / n, w / n
    phi = math.atan2(sw, cu)
    rw = rho - c.L45 * cu
    zw = z - c.L1 - c.L45 * sw
    d = (rw * rw + zw * zw - c.L2 * c.L2 - c.L3 * c.L3) / (2.0 * c.L2 * c.L3)
    if d > 1.0 or d < -1.0:
        if abs(d) > 1.0 + _REACH_EPS:
            return math.hypot(rw, zw)
        d = 1.0 if d > 0.0 else -1.0
    t3 = math.acos(d)
    bend = math.atan2(c.L3 * math.sin(t3), c.L2 + c.L3 * d)
    front = math.atan2(zw, rw)
    over = math.atan2(zw, -rw)
    phi_o = math.pi - phi
    q2fu, q2fd = front + bend, front - bend
    q2ou, q2od = over + bend, over - bend
    t1o = theta + math.pi
    r5o = roll + math.pi
    return (
        (theta, q2fu, -t3, phi - q2fu + t3, roll),
        (theta, q2fd, t3, phi - q2fd - t3, roll),
        (t1o, q2ou, -t3, phi_o - q2ou + t3, r5o),
        (t1o, q2od, t3, phi_o - q2od - t3, r5o),
    )


def _into(v: float, lo: float, hi: float) -> float | None:
    """The 2 pi representative of ``v`` in ``[lo, hi]`` (tolerances included), or None."""
    if v < lo:
        v += TAU * math.ceil((lo - v) / TAU)
    elif v > hi:
        v -= TAU * math.ceil((v - hi) / TAU)
    return v if lo <= v <= hi else None


def _fit_fast(
    c: ArmConstants, qb: tuple[float, ...], s: tuple[float, ...]
) -> tuple[float, ...] | None:
    """Bring every joint of one branch into range (nearest the seed), or None if one cannot."""
    out = []
    lo, hi, full = c.lo, c.hi, c.full_turn
    for j in (1, 2, 3, 4, 0):  # the arm joints fail first on the ASEA; q1 last
        v = qb[j]
        if not (lo[j] <= v <= hi[j]):
            v = _into(v, lo[j], hi[j])  # type: ignore[assignment]
            if v is None:
                return None
        if full[j]:
            v = _nearest_alternative(v, lo[j], hi[j], s[j])
        out.append(v)
    return (out[4], out[0], out[1], out[2], out[3])


def _nearest_alternative(v: float, lo: float, hi: float, ref: float) -> float:
    for alt in (v - TAU, v + TAU):
        if lo <= alt <= hi and abs(alt - ref) < abs(v - ref):
            v = alt
    return v


def ik(
    pose: Sequence[float] | ArrayLike,
    *,
    roll: float = 0.0,
    seed: ArrayLike | None = None,
    model: ArmModel = ASEA,
) -> NDArray[np.float64]:
    """Inverse of chapter eq. 20: the joints of the best branch within the joint ranges.

    Parameters
    ----------
    pose : sequence of 5 floats
        ``(x, y, z, u, w)``: flange position in metres and approach direction
        ``u = cos(q2+q3+q4)``, ``w = sin(q2+q3+q4)`` (see the module docstring); ``(u, w)``
        must be a unit vector within :data:`UNIT_TOL`.
    roll : float
        Rotation of the flange about the approach axis, radians (q5 on the front branches).
    seed : array_like of shape (5,), optional
        Configuration to stay close to (the current joints when moving); default
        ``model.q_home``.  Among the branches within limits the one with the smallest
        Euclidean joint distance to the seed is returned; the seed's q1 is also used when
        the target lies on the q1 axis.
    model : ArmModel
        Link lengths and joint ranges.

    Returns
    -------
    ndarray of shape (5,)
        Joint values in radians, within the ranges (tolerance ``LIMIT_TOL``).

    Raises
    ------
    ValueError
        Malformed pose, position beyond ``MAX_ABS_POSITION_M``, non-unit ``(u, w)``, roll
        not finite or beyond ``MAX_ABS_ROLL_RAD``, or bad seed.
    OutOfReach
        The wrist centre is farther from (or nearer to) the shoulder than L2 + L3 (|L2 - L3|);
        the message gives the distance and the reachable annulus.
    JointLimitsBlock
        Every branch needs a joint outside its range; the message names the joint(s).

    Examples
    --------
    >>> from robot.kinematics import fk
    >>> q = ik((0.8, 0.0, 1.0, 0.0, -1.0))
    >>> bool(np.allclose(fk(q), (0.8, 0.0, 1.0, 0.0, -1.0), atol=1e-12))
    True
    """
    c = arm_constants(model)
    x, y, z, u, w = check_pose(pose)
    roll = _check_roll(roll)
    s = _unpack_seed(seed, c)
    raw = _raw_branches(c, x, y, z, u, w, roll, s[0])
    if isinstance(raw, float):
        raise _out_of_reach(c, (x, y, z), raw)
    best: tuple[float, ...] | None = None
    best_d = math.inf
    for qb in raw:
        fitted = _fit_fast(c, qb, s)
        if fitted is None:
            continue
        dist = (
            (fitted[0] - s[0]) ** 2
            + (fitted[1] - s[1]) ** 2
            + (fitted[2] - s[2]) ** 2
            + (fitted[3] - s[3]) ** 2
            + (fitted[4] - s[4]) ** 2
        )
        if dist < best_d:
            best, best_d = fitted, dist
    if best is None:
        raise _blocked(ik_solutions((x, y, z, u, w), roll=roll, seed=s, model=model))
    return np.array(best)


def ik_solutions(
    pose: Sequence[float] | ArrayLike,
    *,
    roll: float = 0.0,
    seed: ArrayLike | None = None,
    model: ArmModel = ASEA,
) -> list[IKSolution]:
    """Every branch of the inverse of eq. 20, each with its joint-range status.

    Parameters are those of :func:`ik`.  The four branches come in the order of
    :data:`BRANCHES`; at full stretch (``|cos q3| = 1``) elbow up and down coincide but are
    still both listed.

    Returns
    -------
    list of IKSolution
        Four entries; those with ``within_limits`` reproduce the pose exactly.

    Raises
    ------
    ValueError
        Malformed input (see :func:`ik`).
    OutOfReach
        No branch exists: the position is outside the arm's reach.
    """
    c = arm_constants(model)
    x, y, z, u, w = check_pose(pose)
    roll = _check_roll(roll)
    s = _unpack_seed(seed, c)
    raw = _raw_branches(c, x, y, z, u, w, roll, s[0])
    if isinstance(raw, float):
        raise _out_of_reach(c, (x, y, z), raw)
    lo_true = model.lower
    hi_true = model.upper
    out = []
    for name, qb in zip(BRANCHES, raw, strict=True):
        q = np.empty(5)
        bad: list[int] = []
        notes: list[str] = []
        for j in range(5):
            v, inside = _fit_or_closest(qb[j], c.lo[j], c.hi[j], s[j])
            q[j] = v
            if not inside:
                bad.append(j + 1)
                notes.append(
                    f"q{j + 1} = {math.degrees(v):.2f} deg outside "
                    f"[{math.degrees(lo_true[j]):.2f}, {math.degrees(hi_true[j]):.2f}] deg"
                )
        q.setflags(write=False)
        out.append(IKSolution(q, name, not bad, tuple(bad), "; ".join(notes)))
    return out


def _fit_or_closest(v: float, lo: float, hi: float, ref: float) -> tuple[float, bool]:
    """In-range representative nearest ``ref``, else the principal value in (-pi, pi]."""
    inside = _into(v, lo, hi)
    if inside is not None:
        return _nearest_alternative(inside, lo, hi, ref), True
    return math.atan2(math.sin(v), math.cos(v)), False


# -- failures -----------------------------------------------------------------------------------
def _out_of_reach(c: ArmConstants, p: tuple[float, float, float], dist: float) -> OutOfReach:
    rmin, rmax = abs(c.L2 - c.L3), c.L2 + c.L3
    by = dist - rmax if dist > rmax else rmin - dist
    side = "too far from" if dist > rmax else "too close to"
    return OutOfReach(
        f"position ({p[0]:.4f}, {p[1]:.4f}, {p[2]:.4f}) m is out of reach: the wrist centre "
        f"would be {dist:.4f} m from the shoulder, {side} it by {by:.4g} m (reachable "
        f"distances {rmin:.4f} to {rmax:.4f} m, L2 = {c.L2:.3f} m, L3 = {c.L3:.3f} m)"
    )


def _blocked(solutions: list[IKSolution]) -> JointLimitsBlock:
    common = set(solutions[0].violated_joints)
    for s in solutions[1:]:
        common &= set(s.violated_joints)
    joints = tuple(sorted(common))
    head = (
        f"{', '.join(f'q{j}' for j in joints)} block{'s' if len(joints) == 1 else ''} every branch"
        if joints
        else "every branch is blocked by a joint range"
    )
    branches = "; ".join(f"{s.branch}: {s.detail}" for s in solutions)
    return JointLimitsBlock(f"no solution within the joint limits: {head} ({branches})", joints)


def pose_from_flange(
    p: ArrayLike, approach: ArrayLike, *, seed_q1: float = 0.0
) -> tuple[float, float, float, float, float]:
    """The chapter pose ``(x, y, z, u, w)`` of a flange position and approach axis.

    ``approach`` (3,) must lie in the vertical plane through the base z axis and ``p``
    (see the module docstring); ``u`` is its component along the outward horizontal
    direction of that plane (``seed_q1`` gives the plane when ``p`` is on the axis).
    """
    pa = np.asarray(p, dtype=np.float64).reshape(3)
    a = np.asarray(approach, dtype=np.float64).reshape(3)
    rho = math.hypot(pa[0], pa[1])
    theta = math.atan2(pa[1], pa[0]) if rho > _AXIS_EPS else seed_q1
    u = a[0] * math.cos(theta) + a[1] * math.sin(theta)
    n = math.hypot(u, a[2])
    return float(pa[0]), float(pa[1]), float(pa[2]), float(u / n), float(a[2] / n)
