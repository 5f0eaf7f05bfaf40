"""The pinhole camera with lens distortion (chapter section 3.1, equations 1-5).

Conventions: the camera frame is OpenCV's (+z forward, +x right, +y down); pixel
coordinates are ``(u, v)`` with the origin at the centre of the top-left pixel.  The
distortion model is Brown-Conrady as in OpenCV, ``dist = (k1, k2, p1, p2[, k3])``:

    x_d = x (1 + k1 r^2 + k2 r^4 + k3 r^6) + 2 p1 x y + p2 (r^2 + 2 x^2)
    y_d = y (1 + k1 r^2 + k2 r^4 + k3 r^6) + p1 (r^2 + 2 y^2) + 2 p2 x y

with ``r^2 = x^2 + y^2`` on normalised image coordinates.  This is the chapter's eq. 3 and
eq. 5; its eq. 4 prints the tangential term of ``y`` with p1 and p2 swapped, which would
make the model asymmetric in x and y; we follow the symmetric form above, which is what
OpenCV and Brown (1966) use.  ``r`` here is the undistorted radius (the chapter calls it the
distorted radius, but evaluates it on the ideal coordinates).

The simulator's lens applies exactly this code to its renders, so calibration has a
ground truth.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["PinholeCamera", "check_K", "check_dist"]


def check_K(K: ArrayLike) -> NDArray[np.float64]:
    """Validate an intrinsic matrix (eq. 2) and return it as float64 (3, 3)."""
    Ka = np.asarray(K, dtype=np.float64)
    if Ka.shape != (3, 3):
        raise ValueError(f"K must have shape (3, 3), got {Ka.shape}")
    if not np.all(np.isfinite(Ka)):
        raise ValueError(f"K contains NaN or infinity: {Ka.tolist()}")
    if Ka[0, 0] <= 0 or Ka[1, 1] <= 0:
        raise ValueError(f"K focal lengths must be positive, got fx={Ka[0, 0]}, fy={Ka[1, 1]}")
    if not np.allclose(Ka[2], [0.0, 0.0, 1.0]) or Ka[1, 0] != 0.0:
        raise ValueError(f"K must be upper triangular with last row (0, 0, 1), got {Ka.tolist()}")
    return Ka


def check_dist(dist: ArrayLike | None) -> NDArray[np.float64]:
    """Validate ``(k1, k2, p1, p2[, k3])`` and return it as float64 of length 5."""
    if dist is None:
        return np.zeros(5)
    d = np.asarray(dist, dtype=np.float64).ravel()
    if d.size not in (4, 5):
        raise ValueError(f"dist must have 4 or 5 coefficients (k1, k2, p1, p2[, k3]), got {d.size}")
    if not np.all(np.isfinite(d)):
        raise ValueError(f"dist contains NaN or infinity: {d.tolist()}")
    return np.concatenate([d, np.zeros(5 - d.size)])


def _check_points(points: ArrayLike, dim: int, name: str) -> NDArray[np.float64]:
    p = np.asarray(points, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != dim:
        raise ValueError(f"{name} must have shape (N, {dim}), got {p.shape}")
    return p


@dataclass(frozen=True)
class PinholeCamera:
    """Pinhole camera ``x = K [R | t] X`` (eq. 1) with Brown-Conrady distortion (eqs. 3-5).

    Parameters
    ----------
    K : ndarray of shape (3, 3)
        Intrinsic matrix (eq. 2): focal lengths ``fx, fy`` and principal point ``cx, cy``
        in pixels.
    dist : ndarray of shape (5,)
        ``(k1, k2, p1, p2, k3)``; four coefficients are accepted and padded with k3 = 0.
    width, height : int
        Image size in pixels.
    """

    K: NDArray[np.float64]
    dist: NDArray[np.float64]
    width: int
    height: int

    def __init__(
        self, K: ArrayLike, dist: ArrayLike | None = None, *, width: int = 640, height: int = 480
    ) -> None:
        if int(width) <= 0 or int(height) <= 0:
            raise ValueError(f"image size must be positive, got width={width}, height={height}")
        Ka = check_K(K)
        d = check_dist(dist)
        Ka.setflags(write=False)
        d.setflags(write=False)
        object.__setattr__(self, "K", Ka)
        object.__setattr__(self, "dist", d)
        object.__setattr__(self, "width", int(width))
        object.__setattr__(self, "height", int(height))

    # -- construction helpers ------------------------------------------------------------
    @classmethod
    def from_fov(
        cls, fovy_deg: float, *, width: int = 640, height: int = 480, dist: ArrayLike | None = None
    ) -> PinholeCamera:
        """Square-pixel camera with vertical field of view ``fovy_deg`` and a centred principal point."""
        if not 0.0 < fovy_deg < 180.0:
            raise ValueError(f"fovy_deg must be in (0, 180), got {fovy_deg!r}")
        f = 0.5 * height / math.tan(math.radians(fovy_deg) / 2.0)
        K = np.array([[f, 0.0, (width - 1) / 2.0], [0.0, f, (height - 1) / 2.0], [0.0, 0.0, 1.0]])
        return cls(K, dist, width=width, height=height)

    @property
    def fx(self) -> float:
        """Focal length along x, pixels."""
        return float(self.K[0, 0])

    @property
    def fy(self) -> float:
        """Focal length along y, pixels."""
        return float(self.K[1, 1])

    @property
    def cx(self) -> float:
        """Principal point x, pixels."""
        return float(self.K[0, 2])

    @property
    def cy(self) -> float:
        """Principal point y, pixels."""
        return float(self.K[1, 2])

    def fov_deg(self) -> tuple[float, float]:
        """Horizontal and vertical field of view of the undistorted pinhole, degrees."""
        fovx = math.degrees(
            math.atan2(self.cx + 0.5, self.fx) + math.atan2(self.width - 0.5 - self.cx, self.fx)
        )
        fovy = math.degrees(
            math.atan2(self.cy + 0.5, self.fy) + math.atan2(self.height - 0.5 - self.cy, self.fy)
        )
        return fovx, fovy

    # -- distortion (eqs. 3-5) -----------------------------------------------------------
    def distort_normalized(self, xy: ArrayLike) -> NDArray[np.float64]:
        """Apply eqs. 3-5 to normalised coordinates, (N, 2) -> (N, 2)."""
        p = _check_points(xy, 2, "xy")
        k1, k2, p1, p2, k3 = self.dist
        x, y = p[:, 0], p[:, 1]
        r2 = x * x + y * y
        radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
        xd = x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x)
        yd = y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y
        return np.stack([xd, yd], axis=1)

    def undistort_normalized(
        self, xy_d: ArrayLike, *, max_iter: int = 50, tol: float = 1e-14
    ) -> NDArray[np.float64]:
        """Invert eqs. 3-5 by Newton iteration on normalised coordinates, (N, 2) -> (N, 2).

        Newton's method with the analytic 2x2 Jacobian converges quadratically for the
        distortions of real lenses; iteration stops when every point moved less than ``tol``.
        """
        pd = _check_points(xy_d, 2, "xy_d")
        k1, k2, p1, p2, k3 = self.dist
        if not np.any(self.dist):
            return pd.copy()
        x, y = pd[:, 0].copy(), pd[:, 1].copy()
        for _ in range(max_iter):
            r2 = x * x + y * y
            radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
            drad = k1 + r2 * (2.0 * k2 + 3.0 * k3 * r2)  # d(radial)/d(r2)
            fx = x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x) - pd[:, 0]
            fy = y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y - pd[:, 1]
            j11 = radial + 2.0 * x * x * drad + 2.0 * p1 * y + 6.0 * p2 * x
            j12 = 2.0 * x * y * drad + 2.0 * p1 * x + 2.0 * p2 * y
            j21 = 2.0 * x * y * drad + 2.0 * p1 * x + 2.0 * p2 * y
            j22 = radial + 2.0 * y * y * drad + 6.0 * p1 * y + 2.0 * p2 * x
            det = j11 * j22 - j12 * j21
            dx = (j22 * fx - j12 * fy) / det
            dy = (j11 * fy - j21 * fx) / det
            x -= dx
            y -= dy
            if max(np.abs(dx).max(initial=0.0), np.abs(dy).max(initial=0.0)) < tol:
                break
        return np.stack([x, y], axis=1)

    # -- projection (eqs. 1-2) -----------------------------------------------------------
    def project(self, points_cam: ArrayLike) -> NDArray[np.float64]:
        """Project 3D points in the camera frame to distorted pixels, (N, 3) -> (N, 2).

        Points at or behind the camera (z <= 0) project to NaN.
        """
        P = _check_points(points_cam, 3, "points_cam")
        z = P[:, 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            xy = P[:, :2] / z[:, None]
        xy[z <= 0] = np.nan
        return self.pixels_from_normalized(self.distort_normalized(xy))

    def project_world(self, points: ArrayLike, T_cam_world: ArrayLike) -> NDArray[np.float64]:
        """Project points given in another frame through ``T_cam_world`` (4x4), (N, 3) -> (N, 2)."""
        P = _check_points(points, 3, "points")
        T = np.asarray(T_cam_world, dtype=np.float64)
        if T.shape != (4, 4):
            raise ValueError(f"T_cam_world must have shape (4, 4), got {T.shape}")
        return self.project(P @ T[:3, :3].T + T[:3, 3])

    def pixels_from_normalized(self, xy: ArrayLike) -> NDArray[np.float64]:
        """Apply ``K`` to normalised coordinates, (N, 2) -> (N, 2) pixels."""
        p = _check_points(xy, 2, "xy")
        K = self.K
        u = K[0, 0] * p[:, 0] + K[0, 1] * p[:, 1] + K[0, 2]
        v = K[1, 1] * p[:, 1] + K[1, 2]
        return np.stack([u, v], axis=1)

    def normalized_from_pixels(self, uv: ArrayLike) -> NDArray[np.float64]:
        """Invert ``K``: pixels (N, 2) -> normalised coordinates (N, 2) (no undistortion)."""
        p = _check_points(uv, 2, "uv")
        K = self.K
        y = (p[:, 1] - K[1, 2]) / K[1, 1]
        x = (p[:, 0] - K[0, 2] - K[0, 1] * y) / K[0, 0]
        return np.stack([x, y], axis=1)

    def undistort_pixels(self, uv: ArrayLike, *, to_pixels: bool = True) -> NDArray[np.float64]:
        """Remove lens distortion from pixel positions (the inverse of eqs. 3-5).

        Returns undistorted pixels (through the same ``K``) or, with ``to_pixels=False``,
        normalised coordinates as ``cv2.undistortPoints`` does.
        """
        xy = self.undistort_normalized(self.normalized_from_pixels(uv))
        return self.pixels_from_normalized(xy) if to_pixels else xy

    def rays(self, uv: ArrayLike) -> NDArray[np.float64]:
        """Unit viewing rays in the camera frame for distorted pixels, (N, 2) -> (N, 3)."""
        xy = self.undistort_pixels(uv, to_pixels=False)
        r = np.concatenate([xy, np.ones((xy.shape[0], 1))], axis=1)
        return r / np.linalg.norm(r, axis=1, keepdims=True)

    # -- whole images --------------------------------------------------------------------
    def undistort_maps(
        self, K_new: ArrayLike | None = None
    ) -> tuple[NDArray[np.float32], NDArray[np.float32]]:
        """Maps for ``cv2.remap`` that turn a distorted image into an undistorted one.

        For each pixel of the output (a pinhole camera with ``K_new``, default ``K``) the
        maps give where to sample the distorted input: project the pixel's ray through the
        distortion (eqs. 3-5).
        """
        Kn = self.K if K_new is None else check_K(K_new)
        out = PinholeCamera(Kn, None, width=self.width, height=self.height)
        vv, uu = np.mgrid[0 : self.height, 0 : self.width].astype(np.float64)
        xy = out.normalized_from_pixels(np.stack([uu.ravel(), vv.ravel()], axis=1))
        src = self.pixels_from_normalized(self.distort_normalized(xy))
        mx = src[:, 0].reshape(self.height, self.width).astype(np.float32)
        my = src[:, 1].reshape(self.height, self.width).astype(np.float32)
        return mx, my

    def distort_maps(
        self, K_ideal: ArrayLike | None = None
    ) -> tuple[NDArray[np.float32], NDArray[np.float32]]:
        """Maps for ``cv2.remap`` that turn an ideal pinhole image (``K_ideal``, default ``K``)
        into what this lens would record: each output pixel is undistorted (Newton inverse of
        eqs. 3-5) and sampled in the ideal image.  The simulator uses this on its renders.
        """
        Ki = self.K if K_ideal is None else check_K(K_ideal)
        ideal = PinholeCamera(Ki, None, width=self.width, height=self.height)
        vv, uu = np.mgrid[0 : self.height, 0 : self.width].astype(np.float64)
        xy = self.undistort_pixels(np.stack([uu.ravel(), vv.ravel()], axis=1), to_pixels=False)
        src = ideal.pixels_from_normalized(xy)
        mx = src[:, 0].reshape(self.height, self.width).astype(np.float32)
        my = src[:, 1].reshape(self.height, self.width).astype(np.float32)
        return mx, my
