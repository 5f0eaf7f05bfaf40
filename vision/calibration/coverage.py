"""Criteria for a good set of calibration views: image coverage and rotation diversity.

Zhang's method needs the board seen under different tilts, and the lens distortion is only
pinned down where corners were seen, so the views should fill the image (chapter 3.1).
Hand-eye calibration needs robot motions whose rotations are large and turn about
different axes: Tsai and Lenz show that the error of the solution grows as the angle
between the rotation axes of the motions shrinks and as the rotation angles shrink.

References
----------
Z. Zhang, "A flexible new technique for camera calibration", IEEE TPAMI 22(11), 2000.
R. Y. Tsai and R. K. Lenz, "A new technique for fully autonomous and efficient 3D robotics
hand/eye calibration", IEEE Trans. Robotics and Automation 5(3), 1989 (section on
observations 1-4 about the choice of motions).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.spatial.transform import Rotation

__all__ = [
    "CoverageMap",
    "RotationDiversity",
    "ViewSetCriteria",
    "coverage_map",
    "rotation_diversity",
]


@dataclass(frozen=True)
class CoverageMap:
    """Where in the image calibration corners were seen.

    Attributes
    ----------
    counts : ndarray of shape (rows, cols), int
        Corners per grid cell; cell (r, c) spans ``width/cols`` by ``height/rows`` pixels.
    image_size : tuple of int
        ``(width, height)``, pixels.
    """

    counts: NDArray[np.int64]
    image_size: tuple[int, int]

    @property
    def fraction(self) -> float:
        """Fraction of grid cells holding at least one corner, in [0, 1]."""
        return float(np.count_nonzero(self.counts) / self.counts.size)

    @property
    def corner_cells(self) -> int:
        """How many of the four corner cells of the image hold corners (distortion is
        largest there and only measured where corners were seen)."""
        c = self.counts
        return int(sum(c[r, k] > 0 for r in (0, -1) for k in (0, -1)))

    def as_dict(self) -> dict[str, object]:
        """JSON form."""
        return {"counts": self.counts.tolist(), "image_size": list(self.image_size)}

    @classmethod
    def from_dict(cls, d: dict[str, object]) -> CoverageMap:
        """Inverse of :meth:`as_dict`."""
        size = tuple(int(v) for v in d["image_size"])  # type: ignore[attr-defined]
        return cls(np.asarray(d["counts"], dtype=np.int64), (size[0], size[1]))


def coverage_map(
    points: Sequence[ArrayLike], image_size: tuple[int, int], *, grid: tuple[int, int] = (8, 6)
) -> CoverageMap:
    """Count corners per cell of a ``grid = (cols, rows)`` laid over the image.

    Parameters
    ----------
    points : sequence of ndarray of shape (N_i, 2)
        Corner pixels of each view.
    image_size : tuple of int
        ``(width, height)``, pixels.
    grid : tuple of int
        Cells across and down.
    """
    w, h = (int(v) for v in image_size)
    gc, gr = (int(v) for v in grid)
    if w <= 0 or h <= 0:
        raise ValueError(f"image_size must be positive, got {image_size!r}")
    if gc < 1 or gr < 1:
        raise ValueError(f"grid must be at least (1, 1), got {grid!r}")
    counts = np.zeros((gr, gc), dtype=np.int64)
    for p in points:
        a = np.asarray(p, dtype=np.float64).reshape(-1, 2)
        ok = np.isfinite(a).all(axis=1) & (a[:, 0] >= -0.5) & (a[:, 1] >= -0.5)
        ok &= (a[:, 0] < w - 0.5) & (a[:, 1] < h - 0.5)
        a = a[ok]
        c = np.clip(((a[:, 0] + 0.5) * gc / w).astype(int), 0, gc - 1)
        r = np.clip(((a[:, 1] + 0.5) * gr / h).astype(int), 0, gr - 1)
        np.add.at(counts, (r, c), 1)
    return CoverageMap(counts, (w, h))


@dataclass(frozen=True)
class RotationDiversity:
    """How varied a set of orientations is, from the relative rotations of all pairs.

    Attributes
    ----------
    n_poses : int
        Number of orientations.
    max_angle_deg : float
        Largest rotation angle between two of them.
    median_angle_deg : float
        Median rotation angle over all pairs.
    axis_spread_deg : float
        Spread of the rotation axes of the pairs that turn by at least 2 degrees:
        ``2 atan(sqrt(l2 / l1))`` with ``l1 >= l2`` the two largest eigenvalues of the mean
        of ``a a^T`` over the unit axes ``a``.  For two equally weighted axes at angle theta
        this is theta; 0 when all turns are about one axis.
    """

    n_poses: int
    max_angle_deg: float
    median_angle_deg: float
    axis_spread_deg: float

    def as_dict(self) -> dict[str, float | int]:
        """JSON form."""
        return {
            "n_poses": self.n_poses,
            "max_angle_deg": self.max_angle_deg,
            "median_angle_deg": self.median_angle_deg,
            "axis_spread_deg": self.axis_spread_deg,
        }

    @classmethod
    def from_dict(cls, d: dict[str, float | int]) -> RotationDiversity:
        """Inverse of :meth:`as_dict`."""
        return cls(
            int(d["n_poses"]),
            float(d["max_angle_deg"]),
            float(d["median_angle_deg"]),
            float(d["axis_spread_deg"]),
        )


_AXIS_MIN_ANGLE_DEG = 2.0


def rotation_diversity(rotations: ArrayLike) -> RotationDiversity:
    """Diversity of orientations ``rotations`` (N, 3, 3) (or poses (N, 4, 4)).

    For hand-eye calibration pass the robot's ``T_base_ee``: the motions ``A_ij =
    T_base_ee_i^-1 T_base_ee_j`` are what the solvers see.  For intrinsics pass the views'
    ``T_cam_board``.
    """
    R = np.asarray(rotations, dtype=np.float64)
    if R.ndim != 3 or R.shape[1:] not in ((3, 3), (4, 4)):
        raise ValueError(f"rotations must have shape (N, 3, 3) or (N, 4, 4), got {R.shape}")
    R = R[:, :3, :3]
    n = R.shape[0]
    if n < 2:
        return RotationDiversity(n, 0.0, 0.0, 0.0)
    i, j = np.triu_indices(n, k=1)
    rel = np.einsum("nki,nkj->nij", R[i], R[j])  # R_i^T R_j
    rv = Rotation.from_matrix(rel).as_rotvec()
    ang = np.linalg.norm(rv, axis=1)
    ang_deg = np.degrees(ang)
    big = ang_deg >= _AXIS_MIN_ANGLE_DEG
    spread = 0.0
    if np.count_nonzero(big) >= 2:
        axes = rv[big] / ang[big, None]
        lam = np.sort(np.linalg.eigvalsh(axes.T @ axes / axes.shape[0]))[::-1]
        spread = math.degrees(2.0 * math.atan(math.sqrt(max(lam[1], 0.0) / lam[0])))
    return RotationDiversity(n, float(ang_deg.max()), float(np.median(ang_deg)), spread)


@dataclass(frozen=True)
class ViewSetCriteria:
    """When a set of calibration views is good enough to stop collecting.

    Attributes
    ----------
    min_views : int
        Views with the board found.
    min_coverage : float
        Fraction of the coverage grid holding corners.
    min_corner_cells : int
        Image corner cells (of 4) holding corners.
    min_max_angle_deg : float
        Largest rotation between two views (or robot poses).
    min_axis_spread_deg : float
        Spread of rotation axes (see :class:`RotationDiversity`).
    """

    min_views: int = 12
    min_coverage: float = 0.7
    min_corner_cells: int = 3
    min_max_angle_deg: float = 30.0
    min_axis_spread_deg: float = 30.0

    def unmet(self, coverage: CoverageMap, diversity: RotationDiversity) -> list[str]:
        """The criteria not met yet, as sentences; empty when collection may stop."""
        out = []
        if diversity.n_poses < self.min_views:
            out.append(f"{diversity.n_poses} views, need {self.min_views}")
        if coverage.fraction < self.min_coverage:
            out.append(
                f"corners cover {coverage.fraction:.0%} of the image, need {self.min_coverage:.0%}"
            )
        if coverage.corner_cells < self.min_corner_cells:
            out.append(
                f"corners seen in {coverage.corner_cells} image corners, need {self.min_corner_cells}"
            )
        if diversity.max_angle_deg < self.min_max_angle_deg:
            out.append(
                f"largest rotation between views {diversity.max_angle_deg:.1f} deg, "
                f"need {self.min_max_angle_deg:g}"
            )
        if diversity.axis_spread_deg < self.min_axis_spread_deg:
            out.append(
                f"rotation axes spread {diversity.axis_spread_deg:.1f} deg, "
                f"need {self.min_axis_spread_deg:g}"
            )
        return out
