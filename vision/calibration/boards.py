"""Calibration targets: chessboards and ChArUco boards, their geometry and their text forms.

The board frame (``board`` in ``T_cam_board``) has its origin at the first inner corner, x
along the first row of inner corners, y along the first column and z = x × y, which points
*into* the board when it is seen from its printed side (so a camera facing the board has its
+z roughly along the board's +z).  All lengths are metres.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

__all__ = [
    "ARUCO_DICTIONARIES",
    "MAX_BOARD_SIDE",
    "MAX_SQUARE_M",
    "MIN_SQUARE_M",
    "Board",
    "CharucoBoard",
    "Chessboard",
    "board_from_dict",
    "parse_board_size",
    "parse_length_m",
]

#: The ArUco dictionaries a ChArUco board may use (names of ``cv2.aruco.DICT_*``).
ARUCO_DICTIONARIES = (
    "DICT_4X4_50",
    "DICT_4X4_100",
    "DICT_4X4_250",
    "DICT_4X4_1000",
    "DICT_5X5_50",
    "DICT_5X5_100",
    "DICT_5X5_250",
    "DICT_5X5_1000",
    "DICT_6X6_50",
    "DICT_6X6_100",
    "DICT_6X6_250",
    "DICT_6X6_1000",
    "DICT_7X7_50",
    "DICT_7X7_100",
    "DICT_7X7_250",
    "DICT_7X7_1000",
    "DICT_ARUCO_ORIGINAL",
)


#: Most inner corners (chessboard) or squares (ChArUco) along one side of a board: real
#: targets have a few dozen; OpenCV's detectors slow down sharply past this.
MAX_BOARD_SIDE = 100
#: Side of a square, metres: from 1 mm (printed micro-targets) to 1 m (a wall board).
MIN_SQUARE_M = 1e-3
MAX_SQUARE_M = 1.0


def _positive_length(name: str, value: float) -> float:
    if isinstance(value, bool | np.bool_):
        raise ValueError(f"{name} must be a length in metres, not a boolean, got {value!r}")
    v = float(value)
    if not (MIN_SQUARE_M <= v <= MAX_SQUARE_M):
        raise ValueError(
            f"{name} must be a length in [{MIN_SQUARE_M:g}, {MAX_SQUARE_M:g}] m, got {value!r}"
        )
    return v


def _side(name: str, value: int, what: str) -> int:
    if (
        isinstance(value, bool | np.bool_)
        or not isinstance(value, int | np.integer | float)
        or int(value) != value
        or not (3 <= value <= MAX_BOARD_SIDE)
    ):
        raise ValueError(
            f"{name} must be an integer in [3, {MAX_BOARD_SIDE}] ({what}), got {value!r}"
        )
    return int(value)


@dataclass(frozen=True)
class Chessboard:
    """A chessboard counted by its *inner* corners.

    Attributes
    ----------
    cols : int
        Inner corners along a row (OpenCV's ``patternSize.width``), 3 .. MAX_BOARD_SIDE.
    rows : int
        Inner corners along a column (``patternSize.height``), 3 .. MAX_BOARD_SIDE.
    square_m : float
        Side of one square, metres, MIN_SQUARE_M .. MAX_SQUARE_M.
    """

    cols: int
    rows: int
    square_m: float

    def __post_init__(self) -> None:
        for name in ("cols", "rows"):
            object.__setattr__(self, name, _side(name, getattr(self, name), "inner corners"))
        object.__setattr__(self, "square_m", _positive_length("square_m", self.square_m))

    @property
    def pattern_size(self) -> tuple[int, int]:
        """``(cols, rows)`` as OpenCV's detectors take it."""
        return (int(self.cols), int(self.rows))

    @property
    def n_corners(self) -> int:
        """Number of inner corners."""
        return int(self.cols * self.rows)

    @property
    def orientation_unique(self) -> bool:
        """True if the detected corner order, and so the board frame, is unique.

        A square pattern is ambiguous up to 90 degrees.  Otherwise the detector may still
        return the corners rotated by 180 degrees; the square colours settle that only when
        ``cols + rows`` is odd (the first and the last square then differ in colour).
        Hand-eye calibration needs a unique board frame; intrinsics do not.
        """
        return self.cols != self.rows and (self.cols + self.rows) % 2 == 1

    def object_points(self) -> NDArray[np.float64]:
        """Inner corners in the board frame, (cols*rows, 3), row by row, metres."""
        jj, ii = np.mgrid[0 : self.rows, 0 : self.cols]
        pts = np.zeros((self.n_corners, 3))
        pts[:, 0] = ii.ravel() * self.square_m
        pts[:, 1] = jj.ravel() * self.square_m
        return pts

    def describe(self) -> str:
        """Human-readable form, e.g. ``chessboard 9x6, 25 mm squares``."""
        return f"chessboard {self.cols}x{self.rows}, {self.square_m * 1e3:g} mm squares"

    def as_dict(self) -> dict[str, Any]:
        """JSON form (stored with calibration sessions)."""
        return {
            "type": "chessboard",
            "cols": self.cols,
            "rows": self.rows,
            "square_m": self.square_m,
        }


@dataclass(frozen=True)
class CharucoBoard:
    """A ChArUco board (chessboard with ArUco markers in its white squares).

    Attributes
    ----------
    squares_x, squares_y : int
        Number of *squares* along x and y (the inner corners are one fewer each way).
    square_m : float
        Side of one chessboard square, metres.
    marker_m : float
        Side of one ArUco marker, metres (smaller than ``square_m``).
    dictionary : str
        Name of the ArUco dictionary, one of :data:`ARUCO_DICTIONARIES`.
    legacy : bool
        Boards printed before OpenCV 4.6 with an even number of rows put a marker in the
        top-left square; set this for them.

    References
    ----------
    Garrido-Jurado et al., "Automatic generation and detection of highly reliable fiducial
    markers under occlusion", Pattern Recognition 47(6), 2014.
    """

    squares_x: int
    squares_y: int
    square_m: float
    marker_m: float
    dictionary: str = "DICT_5X5_100"
    legacy: bool = False

    def __post_init__(self) -> None:
        for name in ("squares_x", "squares_y"):
            object.__setattr__(self, name, _side(name, getattr(self, name), "squares"))
        object.__setattr__(self, "square_m", _positive_length("square_m", self.square_m))
        object.__setattr__(self, "marker_m", _positive_length("marker_m", self.marker_m))
        if self.marker_m >= self.square_m:
            raise ValueError(
                f"marker_m must be smaller than square_m, got marker_m={self.marker_m!r} "
                f"and square_m={self.square_m!r}"
            )
        if self.dictionary not in ARUCO_DICTIONARIES:
            raise ValueError(
                f"dictionary must be one of {', '.join(ARUCO_DICTIONARIES)}, got {self.dictionary!r}"
            )
        n_markers = (self.squares_x * self.squares_y) // 2
        capacity = int(self.dictionary.rsplit("_", 1)[-1]) if "X" in self.dictionary else 1024
        if n_markers > capacity:
            raise ValueError(
                f"a {self.squares_x}x{self.squares_y} ChArUco board needs {n_markers} markers "
                f"but {self.dictionary} has {capacity}"
            )

    @property
    def n_corners(self) -> int:
        """Number of ChArUco (inner chessboard) corners."""
        return int((self.squares_x - 1) * (self.squares_y - 1))

    @property
    def orientation_unique(self) -> bool:
        """Always True: the marker ids fix the board frame."""
        return True

    def object_points(self) -> NDArray[np.float64]:
        """ChArUco corners in the board frame, (n_corners, 3), in id order, metres.

        Corner ``id`` sits at column ``id % (squares_x - 1)`` and row
        ``id // (squares_x - 1)``, as in OpenCV, whose board origin is the outer corner;
        ours is the first inner corner, so both board kinds share one frame convention.
        """
        nx, ny = self.squares_x - 1, self.squares_y - 1
        jj, ii = np.mgrid[0:ny, 0:nx]
        pts = np.zeros((nx * ny, 3))
        pts[:, 0] = ii.ravel() * self.square_m
        pts[:, 1] = jj.ravel() * self.square_m
        return pts

    def to_cv(self) -> Any:
        """The ``cv2.aruco.CharucoBoard`` of this board."""
        import cv2

        d = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, self.dictionary))
        b = cv2.aruco.CharucoBoard(
            (int(self.squares_x), int(self.squares_y)), self.square_m, self.marker_m, d
        )
        b.setLegacyPattern(bool(self.legacy))
        return b

    def describe(self) -> str:
        """Human-readable form."""
        return (
            f"ChArUco {self.squares_x}x{self.squares_y} squares, {self.square_m * 1e3:g} mm "
            f"squares, {self.marker_m * 1e3:g} mm markers, {self.dictionary}"
        )

    def as_dict(self) -> dict[str, Any]:
        """JSON form (stored with calibration sessions)."""
        return {
            "type": "charuco",
            "squares_x": self.squares_x,
            "squares_y": self.squares_y,
            "square_m": self.square_m,
            "marker_m": self.marker_m,
            "dictionary": self.dictionary,
            "legacy": self.legacy,
        }


Board = Chessboard | CharucoBoard


def board_from_dict(d: dict[str, Any]) -> Board:
    """Inverse of ``Board.as_dict``; raises ``ValueError`` naming what is wrong."""
    if not isinstance(d, dict):
        raise ValueError(f"board must be an object, got {d!r}")
    kind = d.get("type", "chessboard")
    try:
        if kind == "chessboard":
            return Chessboard(int(d["cols"]), int(d["rows"]), float(d["square_m"]))
        if kind == "charuco":
            return CharucoBoard(
                int(d["squares_x"]),
                int(d["squares_y"]),
                float(d["square_m"]),
                float(d["marker_m"]),
                str(d.get("dictionary", "DICT_5X5_100")),
                bool(d.get("legacy", False)),
            )
    except KeyError as exc:
        raise ValueError(f"board of type {kind!r} needs the field {exc.args[0]!r}") from None
    except TypeError as exc:
        raise ValueError(f"board has a field of the wrong type: {exc}") from None
    raise ValueError(f"board type must be 'chessboard' or 'charuco', got {kind!r}")


_SIZE = re.compile(r"^\s*(\d+)\s*[xX×]\s*(\d+)\s*$")
_LENGTH = re.compile(r"^\s*([0-9]*\.?[0-9]+(?:[eE][-+]?\d+)?)\s*(mm|cm|m)?\s*$")
_UNIT_M = {"mm": 1e-3, "cm": 1e-2, "m": 1.0}


def parse_board_size(text: str) -> tuple[int, int]:
    """``"9x6"`` -> ``(9, 6)`` (inner corners per row and per column).

    Raises
    ------
    ValueError
        ``board must look like 9x6, got '9by6'``.
    """
    m = _SIZE.match(str(text))
    if m is None:
        raise ValueError(f"board must look like 9x6, got {text!r}")
    return int(m.group(1)), int(m.group(2))


def parse_length_m(text: str, *, default_unit: str = "mm", name: str = "square") -> float:
    """A length with an optional unit suffix, in metres: ``"25mm"``, ``"2.5cm"``, ``"0.025m"``.

    A plain number is read in ``default_unit`` (millimetres unless told otherwise): board
    squares are printed and measured in millimetres.
    """
    if default_unit not in _UNIT_M:
        raise ValueError(f"default_unit must be one of mm, cm, m, got {default_unit!r}")
    m = _LENGTH.match(str(text))
    if m is None or float(m.group(1)) <= 0.0:
        raise ValueError(f"{name} must be a positive length like 25mm or 0.025m, got {text!r}")
    return float(m.group(1)) * _UNIT_M[m.group(2) or default_unit]
