"""Finding calibration boards in images: chessboards and ChArUco boards.

Chessboards are found with OpenCV's sector-based detector with its accuracy flag
(Duda and Frese 2018), which locates corners to a fraction of what the classic detector and
``cornerSubPix`` reach; where it fails (boards cut by the image border, strong blur) the
classic detector (``findChessboardCorners`` + ``cornerSubPix``) takes over.  Large images
are searched at a reduced size and the corners are then located again at full resolution
in a crop around the board.  ChArUco boards use OpenCV's current ``aruco`` API
(``CharucoDetector``); their corners are then located again leaving the marker pixels out
(:func:`~vision.calibration.charuco_refine.refine_charuco_corners`).

The corner order is made canonical (see :func:`canonical_corner_order`) so that the board
frame is the same in every image: hand-eye calibration depends on it.

References
----------
A. Duda and U. Frese, "Accurate Detection and Localization of Checkerboard Corners for
Calibration", BMVC 2018 (OpenCV's ``findChessboardCornersSB``).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import NDArray

from vision.calibration.boards import Board, CharucoBoard, Chessboard
from vision.calibration.charuco_refine import refine_charuco_corners
from vision.errors import ImageError

__all__ = [
    "Detection",
    "ProgressFn",
    "canonical_corner_order",
    "detect_pattern",
    "detect_patterns",
    "to_gray",
]

ProgressFn = Callable[[float, str], None]

_SUBPIX_CRITERIA = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 50, 1e-4)


@dataclass(frozen=True)
class Detection:
    """The board corners found in one image (or why none were).

    Attributes
    ----------
    found : bool
        Whether the board was found; when False, ``reason`` says why and the arrays are empty.
    image_points : ndarray of shape (N, 2)
        Corner positions, pixels (OpenCV convention: integer values at pixel centres).
    ids : ndarray of shape (N,), int
        Index of each corner in ``board.object_points()``.
    image_size : tuple of int
        ``(width, height)`` of the image, pixels.
    method : str
        Which detector found it: ``"sb"`` (sector-based, accuracy flag), ``"sb-padded"``
        (the same on an image with a replicated border), ``"classic"``
        (``findChessboardCorners`` + ``cornerSubPix``) or ``"charuco"``.
    reason : str
        Why the board was not found; empty when it was.
    """

    found: bool
    image_points: NDArray[np.float64]
    ids: NDArray[np.int64]
    image_size: tuple[int, int]
    method: str = ""
    reason: str = ""

    @classmethod
    def missing(cls, image_size: tuple[int, int], reason: str) -> Detection:
        """A detection that found nothing, with the reason."""
        return cls(False, np.zeros((0, 2)), np.zeros(0, dtype=np.int64), image_size, "", reason)

    @property
    def n_points(self) -> int:
        """Number of corners found."""
        return int(self.image_points.shape[0])

    def object_points(self, board: Board) -> NDArray[np.float64]:
        """The board-frame positions of the found corners, (N, 3) metres."""
        return board.object_points()[self.ids]


def to_gray(image: NDArray[np.uint8]) -> NDArray[np.uint8]:
    """Validate an image (H, W) or (H, W, 3) RGB uint8 and return it in greyscale."""
    img = np.asarray(image)
    if img.dtype != np.uint8:
        raise ImageError(f"image must be uint8, got dtype {img.dtype}")
    if img.ndim == 2:
        return img
    if img.ndim == 3 and img.shape[2] == 3:
        return np.asarray(cv2.cvtColor(img, cv2.COLOR_RGB2GRAY), dtype=np.uint8)
    raise ImageError(f"image must have shape (H, W) or (H, W, 3), got {img.shape}")


def _square_mean(gray: NDArray[np.uint8], quad: NDArray[np.float64]) -> float:
    """Mean grey level in a small patch at the centre of the square spanned by ``quad`` (4, 2)."""
    centre = quad.mean(axis=0)
    side = float(np.min(np.linalg.norm(quad - np.roll(quad, 1, axis=0), axis=1)))
    k = int(np.clip(side * 0.4, 1, 15)) | 1
    patch = cv2.getRectSubPix(gray, (k, k), (float(centre[0]), float(centre[1])))
    return float(patch.mean())


def canonical_corner_order(
    gray: NDArray[np.uint8], corners: NDArray[np.float64], board: Chessboard
) -> NDArray[np.float64]:
    """Reorder chessboard corners (cols*rows, 2) so that the board frame does not depend on
    which detector found them or how the board is turned in the image.

    Two fixes, both exact permutations of the grid:

    1. Handedness: seen from its printed side the board frame is right-handed with z into
       the board, so in the image the first row must turn clockwise into the first column
       (positive cross product in pixel coordinates, y down).  Otherwise the rows are
       reversed (a mirrored order would put the board frame on the back of the board).
    2. The 180-degree ambiguity: where ``cols + rows`` is odd the first and the last square
       differ in colour; the order is reversed if needed so that the square between the
       first four corners is the dark one.
    """
    w, h = board.pattern_size
    grid = np.asarray(corners, dtype=np.float64).reshape(h, w, 2)
    a = grid[0, 1] - grid[0, 0]
    b = grid[1, 0] - grid[0, 0]
    if a[0] * b[1] - a[1] * b[0] < 0.0:
        grid = grid[::-1]
    if (w + h) % 2 == 1:
        first = _square_mean(gray, np.array([grid[0, 0], grid[0, 1], grid[1, 1], grid[1, 0]]))
        last = _square_mean(
            gray, np.array([grid[-1, -1], grid[-1, -2], grid[-2, -2], grid[-2, -1]])
        )
        if first > last:
            grid = grid[::-1, ::-1]
    return grid.reshape(-1, 2).copy()


def _corner_spacing(corners: NDArray[np.float64], board: Chessboard) -> float:
    w, h = board.pattern_size
    grid = corners.reshape(h, w, 2)
    d = np.concatenate(
        [
            np.linalg.norm(np.diff(grid, axis=1), axis=2).ravel(),
            np.linalg.norm(np.diff(grid, axis=0), axis=2).ravel(),
        ]
    )
    return float(np.median(d))


def _find_sb(gray: NDArray[np.uint8], board: Chessboard, flags: int) -> NDArray[np.float64] | None:
    ok, c = cv2.findChessboardCornersSB(gray, board.pattern_size, flags=flags)
    return np.asarray(c, dtype=np.float64).reshape(-1, 2) if ok else None


def _find_classic(gray: NDArray[np.uint8], board: Chessboard) -> NDArray[np.float64] | None:
    flags = cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE
    ok, c = cv2.findChessboardCorners(gray, board.pattern_size, flags=flags)
    if not ok:
        return None
    c = np.asarray(c, dtype=np.float32).reshape(-1, 1, 2)
    # Search window: a bit less than half a square, so it never reaches the next corner.
    half = int(np.clip(0.4 * _corner_spacing(c.reshape(-1, 2).astype(np.float64), board), 2, 11))
    c = cv2.cornerSubPix(gray, c, (half, half), (-1, -1), _SUBPIX_CRITERIA)
    return np.asarray(c, dtype=np.float64).reshape(-1, 2)


def _find_chessboard(
    gray: NDArray[np.uint8], board: Chessboard, detect_max_side_px: int
) -> tuple[NDArray[np.float64] | None, str]:
    acc = cv2.CALIB_CB_ACCURACY
    hgt, wid = gray.shape
    scale = detect_max_side_px / max(hgt, wid)
    if scale < 1.0:
        # Coarse search at reduced size, then the accurate detector at full resolution in a
        # crop around the board (two squares of margin).  INTER_AREA maps full-resolution
        # pixel p to (p + 0.5) * scale - 0.5.
        small = np.asarray(
            cv2.resize(gray, None, fx=scale, fy=scale, interpolation=cv2.INTER_AREA), np.uint8
        )
        coarse = _find_sb(small, board, cv2.CALIB_CB_NORMALIZE_IMAGE)
        if coarse is None:
            coarse = _find_classic(small, board)
        if coarse is not None:
            coarse = (coarse + 0.5) / scale - 0.5
            margin = 2.0 * _corner_spacing(coarse, board)
            x0, y0 = np.maximum(np.floor(coarse.min(axis=0) - margin), 0).astype(int)
            x1 = int(min(np.ceil(coarse[:, 0].max() + margin), wid))
            y1 = int(min(np.ceil(coarse[:, 1].max() + margin), hgt))
            crop = np.ascontiguousarray(gray[y0:y1, x0:x1])
            fine = _find_sb(crop, board, acc)
            if fine is not None:
                return fine + np.array([x0, y0]), "sb"
            fine = _find_classic(crop, board)
            if fine is not None:
                return fine + np.array([x0, y0]), "classic"
    found = _find_sb(gray, board, acc)
    if found is not None:
        return found, "sb"
    # The sector-based detector misses boards that touch the image border; a replicated
    # border gives it room.
    pad = max(16, int(0.06 * max(hgt, wid)))
    padded = np.asarray(
        cv2.copyMakeBorder(gray, pad, pad, pad, pad, cv2.BORDER_REPLICATE), np.uint8
    )
    found = _find_sb(padded, board, acc)
    if found is not None:
        inside = (found >= pad).all(axis=1) & (found[:, 0] < wid + pad) & (found[:, 1] < hgt + pad)
        if inside.all():
            return found - pad, "sb-padded"
    found = _find_classic(gray, board)
    if found is not None:
        return found, "classic"
    return None, ""


def _detect_charuco(gray: NDArray[np.uint8], board: CharucoBoard, min_corners: int) -> Detection:
    size = (int(gray.shape[1]), int(gray.shape[0]))
    detector = cv2.aruco.CharucoDetector(board.to_cv())
    corners, ids, _marker_corners, marker_ids = detector.detectBoard(gray)
    n_markers = 0 if marker_ids is None else len(marker_ids)
    n = 0 if ids is None else len(ids)
    if n < min_corners:
        return Detection.missing(
            size,
            f"only {n} ChArUco corners found ({n_markers} markers), need at least {min_corners}",
        )
    pts = np.asarray(corners, dtype=np.float64).reshape(-1, 2)
    idx = np.asarray(ids, dtype=np.int64).ravel()
    pts = refine_charuco_corners(gray, pts, idx, board)
    order = np.argsort(idx)
    return Detection(True, pts[order], idx[order], size, "charuco", "")


def detect_pattern(
    image: NDArray[np.uint8],
    board: Board,
    *,
    detect_max_side_px: int = 1280,
    min_charuco_corners: int = 6,
) -> Detection:
    """Find ``board`` in ``image``.

    Parameters
    ----------
    image : ndarray of shape (H, W) or (H, W, 3), uint8
        Greyscale or RGB image.
    board : Chessboard or CharucoBoard
        The target to look for.
    detect_max_side_px : int
        Chessboards in images larger than this are first searched at this size, then
        located at full resolution around where they were found.
    min_charuco_corners : int
        A ChArUco detection with fewer corners is reported as not found.

    Returns
    -------
    Detection
        ``found`` False with a ``reason`` when the board is not in the image; this is not
        an error, so that a batch can keep the other images.

    Examples
    --------
    >>> from vision.calibration import Chessboard, detect_pattern
    >>> import numpy as np
    >>> detect_pattern(np.zeros((48, 64), np.uint8), Chessboard(9, 6, 0.025)).reason
    'no 9x6 chessboard found (sector-based and classic detectors)'
    """
    if int(detect_max_side_px) < 160:
        raise ValueError(f"detect_max_side_px must be >= 160, got {detect_max_side_px!r}")
    if int(min_charuco_corners) < 4:
        raise ValueError(f"min_charuco_corners must be >= 4, got {min_charuco_corners!r}")
    gray = to_gray(image)
    size = (int(gray.shape[1]), int(gray.shape[0]))
    if isinstance(board, CharucoBoard):
        return _detect_charuco(gray, board, int(min_charuco_corners))
    if not isinstance(board, Chessboard):
        raise ValueError(f"board must be a Chessboard or a CharucoBoard, got {board!r}")
    corners, method = _find_chessboard(gray, board, int(detect_max_side_px))
    if corners is None:
        return Detection.missing(
            size,
            f"no {board.cols}x{board.rows} chessboard found (sector-based and classic detectors)",
        )
    ordered = canonical_corner_order(gray, corners, board)
    return Detection(True, ordered, np.arange(board.n_corners, dtype=np.int64), size, method, "")


def detect_patterns(
    images: Sequence[NDArray[np.uint8]],
    board: Board,
    *,
    progress: ProgressFn | None = None,
    **options: int,
) -> list[Detection]:
    """:func:`detect_pattern` on each image, reporting progress as ``(fraction, message)``."""
    out = []
    n = len(images)
    for i, img in enumerate(images):
        out.append(detect_pattern(img, board, **options))
        if progress is not None:
            progress((i + 1) / max(n, 1), f"detected {i + 1}/{n} images")
    return out
