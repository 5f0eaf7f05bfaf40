"""The chapter's fuzzy-IK protocol (section 4.4), reproduced on a stated workspace region.

Section 4.4 reports: after 50 GA cycles the "average sum of squared errors in prediction of
joint variables" over 100 random end-effector poses dropped from 2.339 to 0.000193; on 50
random test poses the SSE per pose lies in 0 to 2e-3 (rad^2, printed as "radians"); an
inference takes under 0.8 ms.  The chapter does not say which region it sampled, whether
"average" means the total over the poses or the mean per pose, nor how "before tuning" was
set up.  :func:`run_chapter_protocol` therefore reports the total and the per-pose mean, and
three stages: untuned (initial MFs, every rule outputting the joint-range centres, the
"intuitive" constants), consequents tuned by gradient descent only, and GA plus gradient
descent.

Regions (:class:`PoseRegion`):

* :data:`STATION_REGION`: the flange poses from which the camera views the inspection
  station (r = 0.8 m, z = 0.55 m): x in [0.55, 1.05] m, y in [-0.15, 0.15] m, z in
  [0.85, 1.05] m and approach angle phi = q2 + q3 + q4 in [-120, -60] deg, which holds the
  top view (flange 0.45 m above the station, tool down) and the two side views 30 deg off
  vertical; poses drawn uniformly in that box, kept when the closed-form IK finds a solution
  within the ranges (about 99 % are);
* :data:`WORKSPACE_REGION`: the whole reachable workspace, q1..q4 uniform within the joint
  ranges, pose by eq. 20.

The roll q5 is not among the inputs ``(x, y, z, u, w)`` and therefore cannot be predicted;
training and test poses use q5 = 0, so the fifth output learns 0 and contributes nothing to
the SSE.  Universes of discourse are the training inputs' ranges.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from robot.kinematics.batch import ik_batch
from robot.kinematics.forward import fk
from robot.kinematics.fuzzy import (
    SugenoIK,
    consequents_least_squares,
    initial_sugeno,
    sse,
    sse_per_pose,
    tune_consequents,
)
from robot.kinematics.fuzzy_ga import GAConfig, GATuning, tune_antecedents
from robot.model import ASEA, ArmModel

__all__ = [
    "CHAPTER",
    "STATION_REGION",
    "WORKSPACE_REGION",
    "ChapterFigures",
    "PoseRegion",
    "ProtocolReport",
    "run_chapter_protocol",
    "sample_poses",
]


@dataclass(frozen=True)
class ChapterFigures:
    """The figures of chapter section 4.4, for side-by-side reports."""

    sse_before: float = 2.339
    sse_after: float = 0.000193
    ga_cycles: int = 50
    n_train: int = 100
    n_test: int = 50
    test_sse_per_pose_max: float = 2e-3
    inference_s: float = 0.8e-3


CHAPTER = ChapterFigures()


@dataclass(frozen=True)
class PoseRegion:
    """A region to draw flange poses from.

    Attributes
    ----------
    name : str
    box : tuple of four (lo, hi) pairs, or None
        Bounds of x, y, z (metres) and of the approach angle phi (radians); None for the
        whole reachable workspace (joint-space sampling).
    """

    name: str
    box: tuple[tuple[float, float], ...] | None

    def describe(self) -> str:
        """One line stating the region."""
        if self.box is None:
            return f"{self.name}: q1..q4 uniform within the joint ranges, q5 = 0"
        (x0, x1), (y0, y1), (z0, z1), (p0, p1) = self.box
        return (
            f"{self.name}: x in [{x0:.2f}, {x1:.2f}] m, y in [{y0:.2f}, {y1:.2f}] m, "
            f"z in [{z0:.2f}, {z1:.2f}] m, phi in [{math.degrees(p0):.0f}, "
            f"{math.degrees(p1):.0f}] deg, q5 = 0"
        )


STATION_REGION = PoseRegion(
    "inspection-station viewing region",
    ((0.55, 1.05), (-0.15, 0.15), (0.85, 1.05), (math.radians(-120.0), math.radians(-60.0))),
)
WORKSPACE_REGION = PoseRegion("whole reachable workspace", None)


def sample_poses(
    region: PoseRegion, n: int, rng: np.random.Generator, model: ArmModel = ASEA
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """``n`` random reachable poses of ``region`` and their joints (q5 = 0).

    Returns
    -------
    poses : ndarray of shape (n, 5)
        ``(x, y, z, u, w)``.
    q : ndarray of shape (n, 5)
        Joints within the ranges reaching them (the closed-form solution).
    """
    if n < 1:
        raise ValueError(f"n must be >= 1, got {n!r}")
    if region.box is None:
        q = rng.uniform(model.lower, model.upper, size=(n, 5))
        q[:, 4] = 0.0
        return fk(q, model), q
    lo = np.array([b[0] for b in region.box])
    hi = np.array([b[1] for b in region.box])
    poses_out: list[NDArray[np.float64]] = []
    q_out: list[NDArray[np.float64]] = []
    have = 0
    for _ in range(1000):
        c = rng.uniform(lo, hi, size=(2 * n, 4))
        poses = np.column_stack([c[:, :3], np.cos(c[:, 3]), np.sin(c[:, 3])])
        q, ok = ik_batch(poses, 0.0, model=model)
        poses_out.append(poses[ok])
        q_out.append(q[ok])
        have += int(ok.sum())
        if have >= n:
            return np.vstack(poses_out)[:n], np.vstack(q_out)[:n]
    raise ValueError(f"region {region.name!r} holds almost no reachable poses")


@dataclass(frozen=True)
class ProtocolReport:
    """The chapter's protocol on one region (SSE in rad^2 over the five joints).

    Attributes
    ----------
    region : PoseRegion
    n_train, n_test : int
    sse_untuned : float
        Training SSE of the initial system (MFs dividing the universes, rule outputs at the
        joint-range centres).
    sse_consequents_only : float
        Training SSE after gradient descent on the consequents, MFs untouched.
    sse_tuned : float
        Training SSE after the GA (with consequents re-tuned per individual).
    sse_tuned_least_squares : float
        Training SSE with the GA's MFs and the exact least-squares consequents (the limit
        of the gradient descent), for reference.
    test_sse_per_pose : ndarray of shape (n_test,)
        The tuned system's SSE per test pose (the chapter's Figure 17).
    test_position_error_m : ndarray of shape (n_test,)
        Flange position error of the tuned system's joints, by eq. 20.
    inference_s : float
        Median time of one single-pose inference, seconds.
    gd_learning_rate : float
        ``alpha`` of eq. 23 used for the consequents of the initial MFs.
    initial : SugenoIK
    ga : GATuning
        The GA run; ``ga.fis`` is the tuned system.
    """

    region: PoseRegion
    n_train: int
    n_test: int
    sse_untuned: float
    sse_consequents_only: float
    sse_tuned: float
    sse_tuned_least_squares: float
    test_sse_per_pose: NDArray[np.float64]
    test_position_error_m: NDArray[np.float64]
    inference_s: float
    gd_learning_rate: float
    initial: SugenoIK
    ga: GATuning

    @property
    def fis(self) -> SugenoIK:
        """The tuned system."""
        return self.ga.fis


def run_chapter_protocol(
    region: PoseRegion = STATION_REGION,
    *,
    n_train: int = CHAPTER.n_train,
    n_test: int = CHAPTER.n_test,
    config: GAConfig | None = None,
    seed: int = 0,
    timing_calls: int = 500,
    model: ArmModel = ASEA,
    progress: Callable[[float, str], None] | None = None,
) -> ProtocolReport:
    """Tune the Sugeno IK system as in chapter 3.6.3 and measure it as in section 4.4.

    Parameters
    ----------
    region : PoseRegion
        Where training and test poses are drawn (module docstring).
    n_train, n_test : int
        Training and test poses (chapter: 100 and 50).
    config : GAConfig, optional
        GA settings (default: the chapter's, 50 cycles).
    seed : int
        Seed for drawing the poses (the GA has its own, ``config.seed``).
    timing_calls : int
        Single-pose inferences timed for ``inference_s``.
    model : ArmModel
    progress : callable ``(fraction, message)``, optional
    """
    rng = np.random.default_rng(seed)
    X, Q = sample_poses(region, n_train, rng, model)
    Xt, Qt = sample_poses(region, n_test, rng, model)
    universe = np.column_stack([X.min(axis=0), X.max(axis=0)])
    flat = universe[:, 1] - universe[:, 0] < 1e-9  # a constant input: give it a unit width
    universe[flat] += np.array([-0.5, 0.5])
    fis0 = initial_sugeno(universe, 0.5 * (model.lower + model.upper))
    gd0 = tune_consequents(fis0, X, Q, epochs=(config or GAConfig()).consequent_epochs)
    ga = tune_antecedents(fis0, X, Q, config=config, progress=progress)
    tuned = ga.fis
    pose = Xt[0].copy()
    times = np.empty(timing_calls)
    for i in range(timing_calls):
        t0 = time.perf_counter()
        tuned.infer(pose)
        times[i] = time.perf_counter() - t0
    q_hat = tuned.infer(Xt)
    return ProtocolReport(
        region=region,
        n_train=n_train,
        n_test=n_test,
        sse_untuned=sse(fis0, X, Q),
        sse_consequents_only=sse(gd0.fis, X, Q),
        sse_tuned=sse(tuned, X, Q),
        sse_tuned_least_squares=sse(consequents_least_squares(tuned, X, Q), X, Q),
        test_sse_per_pose=sse_per_pose(tuned, Xt, Qt),
        test_position_error_m=np.linalg.norm(fk(q_hat, model)[:, :3] - Xt[:, :3], axis=1),
        inference_s=float(np.median(times)),
        gd_learning_rate=gd0.learning_rate,
        initial=fis0,
        ga=ga,
    )
