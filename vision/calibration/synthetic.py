"""Synthetic images of calibration boards seen through a known camera (ground truth for tests,
benchmarks and demos where the simulator is not needed).

The renderer casts the ray of every (super-sampled) output pixel through the lens model of
:class:`~vision.camera.PinholeCamera` (the inverse of eqs. 3-5), intersects it with the
board plane and samples a high-resolution picture of the board; the result is averaged
down, blurred a little and given sensor noise.  Corners therefore sit exactly where
``camera.project`` puts them, up to the blur and noise.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import cv2
import numpy as np
from numpy.typing import ArrayLike, NDArray

from vision.calibration.boards import Board, CharucoBoard, Chessboard
from vision.camera import PinholeCamera

__all__ = ["BoardRenderer", "board_picture"]


def board_picture(board: Board, *, px_per_square: int = 48) -> tuple[NDArray[np.uint8], float]:
    """A printable picture of ``board`` with a white margin of one square.

    Returns
    -------
    picture : ndarray of shape (H, W), uint8
        Black and white picture.
    px_per_m : float
        Picture pixels per metre on the board.  Board-frame point ``(x, y)`` (metres, origin
        at the first inner corner) lies at picture pixel ``((x + 2 s) * px_per_m - 0.5,
        (y + 2 s) * px_per_m - 0.5)`` with ``s`` the square side: one square of margin and
        one outer square precede the first inner corner.
    """
    if int(px_per_square) < 4:
        raise ValueError(f"px_per_square must be >= 4, got {px_per_square!r}")
    p = int(px_per_square)
    if isinstance(board, Chessboard):
        nx, ny = board.cols + 1, board.rows + 1
        jj, ii = np.mgrid[0:ny, 0:nx]
        # Square (i, j) of the pattern spans corners i-1..i and j-1..j; square (1, 1), the
        # one between the first four inner corners, is dark (the canonical order's choice).
        dark = (ii + jj) % 2 == 0
        squares = np.where(dark, 0, 255).astype(np.uint8)
        pattern = np.kron(squares, np.ones((p, p), dtype=np.uint8))
    elif isinstance(board, CharucoBoard):
        size = (board.squares_x * p, board.squares_y * p)
        pattern = board.to_cv().generateImage(size, marginSize=0, borderBits=1)
    else:
        raise ValueError(f"board must be a Chessboard or a CharucoBoard, got {board!r}")
    picture = cv2.copyMakeBorder(pattern, p, p, p, p, cv2.BORDER_CONSTANT, value=255)
    return np.asarray(picture, dtype=np.uint8), p / board.square_m


@dataclass
class BoardRenderer:
    """Renders ``board`` as seen by ``camera`` from any board pose.

    Parameters
    ----------
    board : Chessboard or CharucoBoard
        The target.
    camera : PinholeCamera
        Lens and image size of the synthetic camera (eqs. 1-5).
    supersample : int
        Rays per pixel along each axis (anti-aliasing).
    px_per_square : int
        Resolution of the board picture that is sampled.
    """

    board: Board
    camera: PinholeCamera
    supersample: int = 2
    px_per_square: int = 64
    _rays: NDArray[np.float64] = field(init=False, repr=False)
    _picture: NDArray[np.uint8] = field(init=False, repr=False)
    _px_per_m: float = field(init=False, repr=False)

    def __post_init__(self) -> None:
        if int(self.supersample) < 1:
            raise ValueError(f"supersample must be >= 1, got {self.supersample!r}")
        k = int(self.supersample)
        w, h = self.camera.width, self.camera.height
        # Sub-pixel sample positions: pixel u covers [u - 0.5, u + 0.5].
        offs = (np.arange(k) + 0.5) / k - 0.5
        us = (np.arange(w)[:, None] + offs[None, :]).ravel()
        vs = (np.arange(h)[:, None] + offs[None, :]).ravel()
        uu, vv = np.meshgrid(us, vs)
        xy = self.camera.undistort_pixels(
            np.stack([uu.ravel(), vv.ravel()], axis=1), to_pixels=False
        )
        self._rays = np.concatenate([xy, np.ones((xy.shape[0], 1))], axis=1).reshape(
            h * k, w * k, 3
        )
        self._picture, self._px_per_m = board_picture(self.board, px_per_square=self.px_per_square)

    def render(
        self,
        T_cam_board: ArrayLike,
        *,
        blur_sigma_px: float = 0.6,
        noise_std: float = 1.5,
        background: int = 110,
        rng: np.random.Generator | None = None,
    ) -> NDArray[np.uint8]:
        """The greyscale image (H, W) of the board at pose ``T_cam_board`` (4x4, metres).

        ``blur_sigma_px`` is a Gaussian optical blur, ``noise_std`` the standard deviation
        of additive sensor noise in grey levels (needs ``rng`` or uses a fixed seed).
        """
        T = np.asarray(T_cam_board, dtype=np.float64)
        if T.shape != (4, 4):
            raise ValueError(f"T_cam_board must have shape (4, 4), got {T.shape}")
        R, t = T[:3, :3], T[:3, 3]
        n = R[:, 2]
        rays = self._rays
        denom = rays @ n
        with np.errstate(divide="ignore", invalid="ignore"):
            s = float(n @ t) / denom
        hit = rays * s[..., None]  # points on the board plane, camera frame
        pb = (hit - t) @ R  # board frame
        off = 2.0 * self.board.square_m
        mx = ((pb[..., 0] + off) * self._px_per_m - 0.5).astype(np.float32)
        my = ((pb[..., 1] + off) * self._px_per_m - 0.5).astype(np.float32)
        behind = ~(s > 0)
        mx[behind] = -1e6
        my[behind] = -1e6
        big = cv2.remap(
            self._picture,
            mx,
            my,
            interpolation=cv2.INTER_LINEAR,
            borderMode=cv2.BORDER_CONSTANT,
            borderValue=int(background),
        )
        img = big.astype(np.float32)
        # Give the board a printed-paper contrast: black is not 0 and white is not 255.
        img = 20.0 + img * (220.0 / 255.0)
        k = int(self.supersample)
        if k > 1:
            img = np.asarray(
                cv2.resize(
                    img, (self.camera.width, self.camera.height), interpolation=cv2.INTER_AREA
                ),
                dtype=img.dtype,
            )
        if blur_sigma_px > 0:
            img = np.asarray(cv2.GaussianBlur(img, (0, 0), float(blur_sigma_px)), img.dtype)
        if noise_std > 0:
            gen = rng if rng is not None else np.random.default_rng(0)
            img = img + gen.normal(0.0, float(noise_std), img.shape).astype(np.float32)
        return np.clip(np.rint(img), 0, 255).astype(np.uint8)

    def corners(self, T_cam_board: ArrayLike) -> NDArray[np.float64]:
        """The true pixel positions of all board corners at this pose, (n_corners, 2)."""
        return self.camera.project_world(self.board.object_points(), T_cam_board)
