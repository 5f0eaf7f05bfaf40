"""The empty-belt background registered to the belt's travel (chapter 4.1, constant speed).

A still background image of the empty station is right only while the belt stands where it
stood when the image was grabbed: the belt's own pattern (here the painted cross stripes
that show it moving; on a real belt its seams, stains and texture) moves with the belt, so
the background difference of step 1 of the segmentation finds the pattern's old and new
places as well as the object, and they merge with it.  :class:`BeltBackground` models the
view of the empty belt at *any* travel of its encoder:

* ``static``: the per-pixel median of empty frames grabbed at travels spread over the
  belt's whole loop: the scene without the belt's moving pattern (the pattern covers any
  one pixel in only a few of the frames), i.e. the lighting and everything that does not
  move;
* ``ratio``: the belt's pattern as a mosaic in *belt coordinates* ``(u, v)`` (``u`` along
  the loop, modulo its length, ``v`` across), the ratio of each frame to ``static`` at the
  belt points it saw (each pixel back-projected onto the belt plane with the camera model
  and pose), averaged per 2 mm cell;
* :meth:`BeltBackground.at`: the background at travel ``s``: ``static`` times the mosaic
  sampled at ``u = y - y_start - s`` (bilinear, wrapping round the loop) on the belt,
  ``static`` elsewhere.

The travel of a frame is the encoder reading latched with its exposure (the frame's
``meta["belt_travel_m"]``), as a cell latches the encoder count with the camera trigger.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import cv2
import numpy as np
from numpy.typing import NDArray

from vision.camera import PinholeCamera
from vision.errors import InvalidInput
from vision.pose.geometry import plane_points

__all__ = ["BeltBackground", "BeltGeometry", "build_belt_background"]

#: Mosaic cell, metres.
CELL_M = 0.002
#: Fewest frames a belt background is built from, and most.
MIN_FRAMES, MAX_FRAMES = 5, 64


@dataclass(frozen=True)
class BeltGeometry:
    """Where the belt runs (base frame, metres): its centre line ``x = centre_x_m`` along
    ``+y`` from ``start_y_m``, ``width_m`` wide, its surface at ``surface_z_m``, a loop
    ``loop_m`` long (its pattern repeats after that travel)."""

    centre_x_m: float
    start_y_m: float
    width_m: float
    surface_z_m: float
    loop_m: float

    def __post_init__(self) -> None:
        vals = (self.centre_x_m, self.start_y_m, self.width_m, self.surface_z_m, self.loop_m)
        if not all(isinstance(v, int | float) and math.isfinite(v) for v in vals):
            raise InvalidInput(f"belt geometry must be finite numbers, got {vals!r}")
        if not (0.05 <= self.width_m <= 3.0 and 0.1 <= self.loop_m <= 100.0):
            raise InvalidInput(
                f"belt width must be in [0.05, 3] m and loop in [0.1, 100] m, got "
                f"{self.width_m!r}, {self.loop_m!r}"
            )


@dataclass(frozen=True)
class BeltBackground:
    """The empty belt seen from one camera pose, at any travel (module docstring).

    Attributes
    ----------
    static : ndarray of shape (H, W, 3), uint8
        The view without the belt's moving pattern.
    ratio : ndarray of shape (NV, NU, 3), float32
        The pattern's mosaic (1 where the belt is plain).
    u_m, v_m : ndarray of shape (H, W), float32
        Belt coordinates of each pixel at travel 0 (``v`` NaN off the belt).
    geometry : BeltGeometry
    T_base_cam : ndarray of shape (4, 4)
        The camera pose it was grabbed from (it applies to that view only).
    frames : int
        Frames it was built from.
    taken_at : float
        When it was built (``time.time()``): an empty-belt background grabbed later (the
        lights changed) makes it stale.
    """

    static: NDArray[np.uint8]
    ratio: NDArray[np.float32]
    u_m: NDArray[np.float32]
    v_m: NDArray[np.float32]
    geometry: BeltGeometry
    T_base_cam: NDArray[np.float64]
    frames: int
    taken_at: float = field(default_factory=time.time)

    def matches(self, T_base_cam: NDArray[np.float64], *, tol_m: float = 0.002) -> bool:
        """Whether a camera pose is the one this background was grabbed from."""
        T = np.asarray(T_base_cam, dtype=np.float64)
        return bool(
            np.linalg.norm(T[:3, 3] - self.T_base_cam[:3, 3]) <= tol_m
            and np.abs(T[:3, :3] - self.T_base_cam[:3, :3]).max() <= 5e-3
        )

    def at(self, travel_m: float) -> NDArray[np.uint8]:
        """The background image at belt travel ``travel_m`` (metres of the encoder)."""
        if not (isinstance(travel_m, int | float) and math.isfinite(travel_m)):
            raise InvalidInput(f"travel_m must be a finite number, got {travel_m!r}")
        g = self.geometry
        nu = self.ratio.shape[1]
        u = np.mod(self.u_m - np.float32(travel_m), np.float32(g.loop_m)) / np.float32(CELL_M)
        on = np.isfinite(self.v_m)
        v = np.where(on, self.v_m / np.float32(CELL_M), -10.0).astype(np.float32)
        r = cv2.remap(self.ratio, np.mod(u, nu).astype(np.float32), v, cv2.INTER_LINEAR,
                      borderMode=cv2.BORDER_REPLICATE)  # fmt: skip
        r[~on] = 1.0
        out = self.static.astype(np.float32) * r
        return np.clip(out + 0.5, 0, 255).astype(np.uint8)


def _belt_coords(
    shape: tuple[int, int], camera: PinholeCamera, T_base_cam: NDArray[np.float64], g: BeltGeometry
) -> tuple[NDArray[np.float32], NDArray[np.float32]]:
    h, w = shape
    ys, xs = np.mgrid[0:h, 0:w]
    px = np.stack([xs.ravel(), ys.ravel()], axis=1).astype(np.float64)
    pts = plane_points(px, camera, T_base_cam, g.surface_z_m).reshape(h, w, 3)
    u = (pts[..., 1] - g.start_y_m).astype(np.float32)
    lateral = pts[..., 0] - (g.centre_x_m - g.width_m / 2.0)
    on = (lateral >= 0.003) & (lateral <= g.width_m - 0.003)
    v = np.where(on, lateral, np.nan).astype(np.float32)
    return u, v


def build_belt_background(
    frames: list[tuple[NDArray[np.uint8], float]],
    *,
    camera: PinholeCamera,
    T_base_cam: NDArray[np.float64],
    geometry: BeltGeometry,
) -> BeltBackground:
    """Build the belt background from empty frames and their travels (module docstring).

    Parameters
    ----------
    frames : list of (image, travel_m)
        Images of shape (H, W, 3), uint8, of the empty belt from one camera pose, with the
        belt's encoder travel at each exposure; ``MIN_FRAMES``..``MAX_FRAMES`` of them,
        best spread over the whole loop.
    camera : PinholeCamera
        Intrinsics (``K``, ``dist``) of the camera.
    T_base_cam : ndarray of shape (4, 4)
        Its pose when the frames were grabbed.
    geometry : BeltGeometry
    """
    if not MIN_FRAMES <= len(frames) <= MAX_FRAMES:
        raise InvalidInput(
            f"a belt background needs {MIN_FRAMES}..{MAX_FRAMES} frames, got {len(frames)}"
        )
    shape = frames[0][0].shape
    if (
        len(shape) != 3
        or shape[2] != 3
        or any(f.shape != shape or f.dtype != np.uint8 for f, _ in frames)
    ):
        raise InvalidInput("belt background frames must be HxWx3 uint8 images of one size")
    travels = [t for _, t in frames]
    if not all(isinstance(t, int | float) and math.isfinite(t) for t in travels):
        raise InvalidInput(f"frame travels must be finite numbers, got {travels!r}")
    stack = np.stack([f for f, _ in frames])
    static = np.median(stack, axis=0).astype(np.uint8)
    u0, v = _belt_coords(shape[:2], camera, np.asarray(T_base_cam, np.float64), geometry)
    nu = max(1, math.ceil(geometry.loop_m / CELL_M))
    nv = max(1, math.ceil(geometry.width_m / CELL_M) + 1)
    acc = np.zeros((nv * nu, 3), np.float64)
    cnt = np.zeros(nv * nu, np.float64)
    on = np.isfinite(v)
    iv = np.clip(np.round(v[on] / CELL_M).astype(np.int64), 0, nv - 1)
    base = np.maximum(static[on].astype(np.float64), 1.0)
    for img, t in frames:
        iu = np.round(np.mod(u0[on] - t, geometry.loop_m) / CELL_M).astype(np.int64) % nu
        k = iv * nu + iu
        np.add.at(acc, k, img[on].astype(np.float64) / base)
        np.add.at(cnt, k, 1.0)
    ratio = np.ones((nv * nu, 3), np.float64)
    seen = cnt > 0
    ratio[seen] = acc[seen] / cnt[seen, None]
    ratio_img = ratio.reshape(nv, nu, 3).astype(np.float32)
    T = np.asarray(T_base_cam, dtype=np.float64).copy()
    return BeltBackground(static, ratio_img, u0, v, geometry, T, len(frames))
