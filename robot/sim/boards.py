"""Calibration boards for the simulated cell: a chessboard and an OpenCV ChArUco board.

A board is a printed texture on a thin plate.  Board frame (OpenCV's): x to the right along
the printed rows, y down the printed image, z into the plate, so the printed face looks
towards -z.  The origin is the first inner corner (top left) for the chessboard, as in the
usual ``objp = mgrid[0:cols, 0:rows] * square``, and the outer top-left corner of the square
grid for ChArUco, as ``cv2.aruco.CharucoBoard.getChessboardCorners()`` returns (checked on
OpenCV 4.14).
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from dataclasses import dataclass
from functools import cached_property

import cv2
import numpy as np
from numpy.typing import NDArray

from robot.sim import textures as tx
from robot.sim.builder import MjcfBuilder, fmt
from robot.sim.meshes import Mesh

__all__ = ["BOARD_KINDS", "BoardSpec", "add_board_body", "default_boards"]

BOARD_KINDS = ("chessboard", "charuco")


@dataclass(frozen=True)
class BoardSpec:
    """A calibration pattern.

    Attributes
    ----------
    kind : {"chessboard", "charuco"}
    cols, rows : int
        Chessboard: inner corners along x and y (OpenCV's ``patternSize``).  ChArUco:
        squares along x and y.
    square_m : float
        Edge of one square, metres.
    marker_m : float
        ChArUco marker edge, metres (ignored for the chessboard).
    dictionary : str
        ``cv2.aruco`` predefined dictionary name (ChArUco only).
    px_per_square : int
        Texture resolution.
    margin_squares : float
        White margin round the pattern, in squares.
    """

    kind: str
    cols: int
    rows: int
    square_m: float
    marker_m: float = 0.0
    dictionary: str = "DICT_5X5_100"
    px_per_square: int = 64
    margin_squares: float = 0.75

    def __post_init__(self) -> None:
        if self.kind not in BOARD_KINDS:
            raise ValueError(f"kind must be one of {BOARD_KINDS}, got {self.kind!r}")
        if self.cols < 2 or self.rows < 2:
            raise ValueError(f"cols and rows must be >= 2, got {self.cols}, {self.rows}")
        if not 0.0 < self.square_m < 1.0:
            raise ValueError(f"square_m must be in (0, 1) m, got {self.square_m!r}")
        if self.kind == "charuco" and not 0.0 < self.marker_m < self.square_m:
            raise ValueError(
                f"marker_m must be in (0, square_m={self.square_m}) for ChArUco, got {self.marker_m!r}"
            )

    @property
    def margin_px(self) -> int:
        """Margin of the texture, pixels."""
        return round(self.margin_squares * self.px_per_square)

    @property
    def squares(self) -> tuple[int, int]:
        """Squares along x and y."""
        return (
            (self.cols + 1, self.rows + 1) if self.kind == "chessboard" else (self.cols, self.rows)
        )

    def opencv_board(self) -> cv2.aruco.CharucoBoard:
        """The ``cv2.aruco.CharucoBoard`` (ChArUco only)."""
        if self.kind != "charuco":
            raise ValueError(f"opencv_board is for ChArUco boards, this one is a {self.kind}")
        d = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, self.dictionary))
        return cv2.aruco.CharucoBoard((self.cols, self.rows), self.square_m, self.marker_m, d)

    @cached_property
    def image(self) -> NDArray[np.uint8]:
        """The printed face, RGB, row 0 at the top."""
        if self.kind == "chessboard":
            return tx.chessboard_image(
                self.cols,
                self.rows,
                px_per_square=self.px_per_square,
                margin_squares=self.margin_px / self.px_per_square,
            )
        sx, sy = self.squares
        return tx.charuco_image(
            self.opencv_board(), sx, sy, px_per_square=self.px_per_square, margin_px=self.margin_px
        )

    @property
    def origin_px(self) -> float:
        """Texture position of the board frame's origin (same along x and y), in pixel edges."""
        m = self.margin_px
        return float(m + self.px_per_square) if self.kind == "chessboard" else float(m)

    def corners_board(self) -> NDArray[np.float64]:
        """Inner corners in the board frame, shape (N, 3), in OpenCV's order.

        Chessboard: row-major from the origin, x fastest (what ``findChessboardCorners``
        with ``patternSize=(cols, rows)`` pairs with).  ChArUco: ids 0..N-1 as
        ``getChessboardCorners()``.
        """
        if self.kind == "charuco":
            return np.asarray(self.opencv_board().getChessboardCorners(), dtype=np.float64)
        jj, ii = np.mgrid[0 : self.rows, 0 : self.cols]
        pts = np.stack([ii.ravel(), jj.ravel(), np.zeros(ii.size)], axis=1)
        return pts * self.square_m

    def print_extent_m(self) -> tuple[float, float, float, float]:
        """``(x_left, x_right, y_top, y_bottom)`` of the printed face in the board frame."""
        h, w = self.image.shape[:2]
        scale = self.square_m / self.px_per_square
        o = self.origin_px
        return (-o * scale, (w - o) * scale, -o * scale, (h - o) * scale)

    def face_mesh(self) -> Mesh:
        """The printed face: a quad at z = 0 facing -z, texture as printed."""
        xl, xr, yt, yb = self.print_extent_m()
        v = np.array([[xl, yt, 0.0], [xl, yb, 0.0], [xr, yb, 0.0], [xr, yt, 0.0]])
        uv = np.array([[0.0, 1.0], [0.0, 0.0], [1.0, 0.0], [1.0, 1.0]])
        # Counter-clockwise seen from -z (x right, y down on the viewer's screen).
        faces = np.array([[0, 1, 2], [0, 2, 3]])
        return Mesh(v, np.tile([0.0, 0.0, -1.0], (4, 1)), uv, faces)


def default_boards() -> tuple[BoardSpec, BoardSpec]:
    """A 9x6 chessboard with 25 mm squares and an 8x6 ChArUco board with 30 mm squares."""
    return (
        BoardSpec("chessboard", 9, 6, 0.025),
        BoardSpec("charuco", 8, 6, 0.030, marker_m=0.022),
    )


def add_board_body(b: MjcfBuilder, spec: BoardSpec, name: str) -> str:
    """A mocap body carrying the board's printed face and a grey backing plate."""
    tex = b.texture(f"{name}_print", spec.image)
    mat = b.material(f"{name}_print", texture=tex, specular=0.05, shininess=0.1)
    mesh = b.mesh(f"{name}_face", spec.face_mesh())
    b.material(f"{name}_back", rgba=(0.35, 0.36, 0.38, 1), specular=0.2)
    body = ET.SubElement(b.worldbody, "body", name=name, mocap="true", pos="0 0 -5")
    b.visual_geom(body, name=f"{name}_face", type="mesh", mesh=mesh, material=mat)
    xl, xr, yt, yb = spec.print_extent_m()
    b.visual_geom(
        body,
        name=f"{name}_back",
        type="box",
        material=f"{name}_back",
        size=fmt(((xr - xl) / 2, (yb - yt) / 2, 0.002)),
        pos=fmt(((xl + xr) / 2, (yt + yb) / 2, 0.0023)),
    )
    return name
