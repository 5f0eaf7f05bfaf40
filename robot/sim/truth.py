"""Ground truth of the simulated cell, for tests and benchmarks only.

Product algorithms (calibration, recognition, pose estimation) must never read these: they
are the answers those algorithms are judged against.  Reach them explicitly through
``engine.truth`` (a :class:`SimTruth`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike, NDArray

from robot.sim.boards import BoardSpec
from robot.sim.camera import CameraSpec

if TYPE_CHECKING:
    from robot.sim.engine import SimEngine

__all__ = ["BoardTruth", "CameraTruth", "ObjectTruth", "SimTruth"]


def _frozen(a: ArrayLike) -> NDArray[np.float64]:
    out = np.array(a, dtype=np.float64)
    out.setflags(write=False)
    return out


@dataclass(frozen=True)
class CameraTruth:
    """The camera's true model.

    Attributes
    ----------
    K : ndarray (3, 3)
        Intrinsics (chapter eq. 2).
    dist : ndarray (5,)
        ``(k1, k2, p1, p2, k3)`` (chapter eqs. 3-5).
    T_ee_cam : ndarray (4, 4)
        Mounting on the flange (OpenCV camera frame).
    width, height : int
        Image size.
    """

    K: NDArray[np.float64]
    dist: NDArray[np.float64]
    T_ee_cam: NDArray[np.float64]
    width: int
    height: int

    @classmethod
    def from_spec(cls, spec: CameraSpec) -> CameraTruth:
        """Truth of a :class:`CameraSpec`."""
        return cls(
            _frozen(spec.K), _frozen(spec.dist), _frozen(spec.T_ee_cam), spec.width, spec.height
        )


@dataclass(frozen=True)
class ObjectTruth:
    """An object on the belt.

    Attributes
    ----------
    id : int
        Engine-wide id.
    name : str
        Catalogue name.
    T_base_obj : ndarray (4, 4)
        Object frame (footprint centre on the belt surface, z up) in the base frame.
    s_m : float
        Distance along the belt from its entry.
    lateral_m : float
        Offset from the belt's centre line (towards +x of the base).
    yaw_rad : float
        Rotation about z.
    trainable : bool
        False for the parts that recognition must reject.
    """

    id: int
    name: str
    T_base_obj: NDArray[np.float64]
    s_m: float
    lateral_m: float
    yaw_rad: float
    trainable: bool

    def as_dict(self) -> dict[str, object]:
        """JSON-friendly form (the API's object listing)."""
        return {
            "id": self.id,
            "name": self.name,
            "T_base_obj": self.T_base_obj.tolist(),
            "position_m": self.T_base_obj[:3, 3].tolist(),
            "yaw_rad": self.yaw_rad,
            "position_along_belt_m": self.s_m,
            "lateral_m": self.lateral_m,
            "trainable": self.trainable,
        }


@dataclass(frozen=True)
class BoardTruth:
    """A placed calibration board.

    Attributes
    ----------
    spec : BoardSpec
        Pattern and sizes.
    T_base_board : ndarray (4, 4)
        Board frame in the base frame (see :mod:`robot.sim.boards` for the convention).
    """

    spec: BoardSpec
    T_base_board: NDArray[np.float64]

    @property
    def kind(self) -> str:
        """``"chessboard"`` or ``"charuco"``."""
        return self.spec.kind

    @property
    def corners_board(self) -> NDArray[np.float64]:
        """Inner corners in the board frame, (N, 3), OpenCV's order."""
        return self.spec.corners_board()

    @property
    def corners_base(self) -> NDArray[np.float64]:
        """Inner corners in the base frame, (N, 3)."""
        c = self.corners_board
        return c @ self.T_base_board[:3, :3].T + self.T_base_board[:3, 3]

    def as_dict(self) -> dict[str, object]:
        """JSON-friendly form."""
        s = self.spec
        return {
            "kind": s.kind,
            "cols": s.cols,
            "rows": s.rows,
            "square_m": s.square_m,
            "marker_m": s.marker_m if s.kind == "charuco" else None,
            "dictionary": s.dictionary if s.kind == "charuco" else None,
            "T_base_board": self.T_base_board.tolist(),
        }


class SimTruth:
    """Read-only access to the answers: camera model, object and board poses, true camera pose."""

    def __init__(self, engine: SimEngine) -> None:
        self._engine = engine

    @property
    def camera(self) -> CameraTruth:
        """True ``K``, ``dist`` and ``T_ee_cam``."""
        return CameraTruth.from_spec(self._engine.config.camera)

    def objects(self) -> list[ObjectTruth]:
        """Every object on the belt now."""
        return self._engine.objects()

    def object(self, obj_id: int) -> ObjectTruth:
        """One object by id (``KeyError`` if absent)."""
        for o in self._engine.objects():
            if o.id == obj_id:
                return o
        raise KeyError(obj_id)

    def boards(self) -> list[BoardTruth]:
        """Placed calibration boards."""
        return self._engine.boards()

    def board(self, kind: str) -> BoardTruth:
        """The placed board of ``kind`` (``KeyError`` if it is not placed)."""
        for b in self._engine.boards():
            if b.kind == kind:
                return b
        raise KeyError(kind)

    def T_base_cam(self, q: ArrayLike | None = None) -> NDArray[np.float64]:
        """True camera pose for joints ``q`` (default: the arm's current joints)."""
        qa = self._engine.arm_state().q if q is None else np.asarray(q, dtype=np.float64)
        return self._engine.config.camera.T_base_cam(qa, self._engine.arm_model)
