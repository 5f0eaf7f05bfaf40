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

Accepted distortion vectors: ``None`` (no distortion), ``(k1, k2)`` (radial only, the
chapter's recommendation after Tsai 1987), ``(k1, k2, p1, p2)`` and ``(k1, k2, p1, p2, k3)``.
They are stored padded to five coefficients, the layout ``cv2.projectPoints`` accepts.

The simulator's lens applies exactly this code to its renders (:meth:`PinholeCamera.distort_maps`,
:meth:`PinholeCamera.distort_normalized`), so calibration has a ground truth.  Agreement with
OpenCV (``projectPoints``, ``undistortPointsIter``, ``initUndistortRectifyMap``) is tested to
1e-9 in ``tests/vision/test_camera_opencv.py``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = [
    "PinholeCamera",
    "T_from_rvec_tvec",
    "check_K",
    "check_dist",
    "focal_from_fov",
    "fov_from_focal",
    "rotation_from_rvec",
]


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
    """Validate ``(k1, k2[, p1, p2[, k3]])`` and return it as float64 of length 5.

    Two coefficients mean a radial-only lens ``(k1, k2)``; four add the tangential terms;
    five add ``k3``.  Missing coefficients are zero.
    """
    if dist is None:
        return np.zeros(5)
    d = np.asarray(dist, dtype=np.float64).ravel()
    if d.size not in (2, 4, 5):
        raise ValueError(
            "dist must have 2 (k1, k2), 4 (k1, k2, p1, p2) or 5 (k1, k2, p1, p2, k3) "
            f"coefficients, got {d.size}: {d.tolist()}"
        )
    if not np.all(np.isfinite(d)):
        raise ValueError(f"dist contains NaN or infinity: {d.tolist()}")
    return np.concatenate([d, np.zeros(5 - d.size)])


def _check_points(points: ArrayLike, dim: int, name: str) -> NDArray[np.float64]:
    p = np.asarray(points, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != dim:
        raise ValueError(f"{name} must have shape (N, {dim}), got {p.shape}")
    if not np.all(np.isfinite(p)):
        bad = np.flatnonzero(~np.all(np.isfinite(p), axis=1))
        raise ValueError(
            f"{name} contains NaN or infinity at rows {bad[:5].tolist()}"
            f"{'...' if bad.size > 5 else ''}: first bad row {p[bad[0]].tolist()}"
        )
    return p


def rotation_from_rvec(rvec: ArrayLike) -> NDArray[np.float64]:
    """Rotation matrix of an axis-angle vector (Rodrigues' formula), as ``cv2.Rodrigues``.

    Parameters
    ----------
    rvec : array_like of shape (3,)
        Rotation axis times the angle in radians.
    """
    r = np.asarray(rvec, dtype=np.float64).ravel()
    if r.shape != (3,) or not np.all(np.isfinite(r)):
        raise ValueError(f"rvec must be 3 finite numbers, got {np.asarray(rvec).tolist()!r}")
    theta = float(np.linalg.norm(r))
    if theta < 1e-12:
        # First-order expansion R = I + [r]x keeps the tiny-angle case exact to 1e-24.
        kx = np.array([[0.0, -r[2], r[1]], [r[2], 0.0, -r[0]], [-r[1], r[0], 0.0]])
        return np.eye(3) + kx
    k = r / theta
    kx = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    c, s = math.cos(theta), math.sin(theta)
    return c * np.eye(3) + s * kx + (1.0 - c) * np.outer(k, k)


def T_from_rvec_tvec(rvec: ArrayLike, tvec: ArrayLike) -> NDArray[np.float64]:
    """4x4 ``T_cam_world`` from OpenCV's extrinsics ``(rvec, tvec)`` (the ``[R | t]`` of eq. 1)."""
    t = np.asarray(tvec, dtype=np.float64).ravel()
    if t.shape != (3,) or not np.all(np.isfinite(t)):
        raise ValueError(f"tvec must be 3 finite numbers, got {np.asarray(tvec).tolist()!r}")
    T = np.eye(4)
    T[:3, :3] = rotation_from_rvec(rvec)
    T[:3, 3] = t
    return T


def focal_from_fov(fov_deg: float, size_px: int) -> float:
    """Focal length in pixels that spans ``size_px`` pixels with a field of view of ``fov_deg``.

    ``f = (size_px / 2) / tan(fov / 2)`` for a centred principal point (pinhole, eq. 2).
    """
    if not 0.0 < fov_deg < 180.0:
        raise ValueError(f"fov_deg must be in (0, 180), got {fov_deg!r}")
    if size_px <= 0:
        raise ValueError(f"size_px must be positive, got {size_px!r}")
    return 0.5 * size_px / math.tan(math.radians(fov_deg) / 2.0)


def fov_from_focal(f_px: float, size_px: int) -> float:
    """Field of view in degrees of ``size_px`` pixels at focal length ``f_px`` (centred)."""
    if not f_px > 0:
        raise ValueError(f"f_px must be positive, got {f_px!r}")
    if size_px <= 0:
        raise ValueError(f"size_px must be positive, got {size_px!r}")
    return math.degrees(2.0 * math.atan(0.5 * size_px / f_px))


@dataclass(frozen=True)
class PinholeCamera:
    """Pinhole camera ``x = K [R | t] X`` (eq. 1) with Brown-Conrady distortion (eqs. 3-5).

    Parameters
    ----------
    K : ndarray of shape (3, 3)
        Intrinsic matrix (eq. 2): focal lengths ``fx, fy`` and principal point ``cx, cy``
        in pixels (a skew ``K[0, 1]`` is allowed, as in OpenCV).
    dist : array_like of length 2, 4 or 5, or None
        ``(k1, k2[, p1, p2[, k3]])``; stored padded with zeros to ``(k1, k2, p1, p2, k3)``.
    width, height : int
        Image size in pixels.

    Examples
    --------
    >>> cam = PinholeCamera.from_fov(60.0, width=640, height=480)
    >>> cam.project([[0.0, 0.0, 1.0]]).round(1).tolist()
    [[319.5, 239.5]]
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
        f = focal_from_fov(fovy_deg, height)
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

    @property
    def is_radial_only(self) -> bool:
        """True when the tangential coefficients p1, p2 are zero."""
        return bool(self.dist[2] == 0.0 and self.dist[3] == 0.0)

    def fov_deg(self, *, distorted: bool = False) -> tuple[float, float]:
        """Horizontal and vertical field of view, degrees.

        With ``distorted=False`` the angles of the ideal pinhole (eq. 2 only); with
        ``distorted=True`` the angles between the viewing rays through the outer edges of the
        image on the lines through the principal point, after removing the lens distortion
        (barrel distortion widens the view, pincushion narrows it).
        """
        if not distorted:
            fovx = math.degrees(
                math.atan2(self.cx + 0.5, self.fx) + math.atan2(self.width - 0.5 - self.cx, self.fx)
            )
            fovy = math.degrees(
                math.atan2(self.cy + 0.5, self.fy)
                + math.atan2(self.height - 0.5 - self.cy, self.fy)
            )
            return fovx, fovy
        edges = np.array(
            [
                [-0.5, self.cy],
                [self.width - 0.5, self.cy],
                [self.cx, -0.5],
                [self.cx, self.height - 0.5],
            ]
        )
        r = self.rays(edges)
        ang = [math.degrees(math.acos(float(np.clip(r[i] @ r[i + 1], -1.0, 1.0)))) for i in (0, 2)]
        return ang[0], ang[1]

    def fov_diagonal_deg(self) -> float:
        """Field of view across the image diagonal of the ideal pinhole, degrees."""
        a = self.normalized_from_pixels([[-0.5, -0.5]])[0]
        b = self.normalized_from_pixels([[self.width - 0.5, self.height - 0.5]])[0]
        ra, rb = np.append(a, 1.0), np.append(b, 1.0)
        c = ra @ rb / (np.linalg.norm(ra) * np.linalg.norm(rb))
        return math.degrees(math.acos(float(np.clip(c, -1.0, 1.0))))

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
        distortions of real lenses (starting from the distorted point itself); a point is done
        when its step is below ``tol``.  Points that have not converged after ``max_iter``
        steps, and roots off the lens's monotone branch (a mirror image beyond the fold of a
        strongly distorting lens, negative radial factor or Jacobian determinant), come back
        as NaN rather than as a wrong number; ``cv2.remap`` renders NaN as border.
        """
        if max_iter < 1:
            raise ValueError(f"max_iter must be >= 1, got {max_iter!r}")
        if not tol > 0:
            raise ValueError(f"tol must be positive, got {tol!r}")
        pd = _check_points(xy_d, 2, "xy_d")
        k1, k2, p1, p2, k3 = self.dist
        if not np.any(self.dist):
            return pd.copy()
        out = np.full_like(pd, np.nan)
        idx = np.arange(pd.shape[0])
        x, y = pd[:, 0].copy(), pd[:, 1].copy()
        xt, yt = pd[:, 0], pd[:, 1]
        with np.errstate(all="ignore"):
            for _ in range(max_iter):
                if idx.size == 0:
                    break
                r2 = x * x + y * y
                radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
                drad = k1 + r2 * (2.0 * k2 + 3.0 * k3 * r2)  # d(radial)/d(r2)
                fx = x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x) - xt
                fy = y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y - yt
                j11 = radial + 2.0 * x * x * drad + 2.0 * p1 * y + 6.0 * p2 * x
                j12 = 2.0 * x * y * drad + 2.0 * p1 * x + 2.0 * p2 * y
                j22 = radial + 2.0 * y * y * drad + 6.0 * p1 * y + 2.0 * p2 * x
                det = j11 * j22 - j12 * j12  # the Jacobian is symmetric
                dx = (j22 * fx - j12 * fy) / det
                dy = (j11 * fy - j12 * fx) / det
                x = x - dx
                y = y - dy
                done = np.maximum(np.abs(dx), np.abs(dy)) < tol
                if np.any(done):
                    out[idx[done], 0] = x[done]
                    out[idx[done], 1] = y[done]
                    keep = ~done & np.isfinite(x) & np.isfinite(y)
                    idx, x, y, xt, yt = idx[keep], x[keep], y[keep], xt[keep], yt[keep]
            # A root is physical only on the lens's monotone branch: positive radial factor
            # and positive Jacobian determinant (else it is a mirror image beyond the fold).
            x, y = out[:, 0], out[:, 1]
            r2 = x * x + y * y
            radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
            drad = k1 + r2 * (2.0 * k2 + 3.0 * k3 * r2)
            j11 = radial + 2.0 * x * x * drad + 2.0 * p1 * y + 6.0 * p2 * x
            j12 = 2.0 * x * y * drad + 2.0 * p1 * x + 2.0 * p2 * y
            j22 = radial + 2.0 * y * y * drad + 6.0 * p1 * y + 2.0 * p2 * x
            out[~((radial > 0) & (j11 * j22 - j12 * j12 > 0))] = np.nan
        return out

    # -- projection (eqs. 1-2) -----------------------------------------------------------
    def project(
        self, points_cam: ArrayLike, *, behind: Literal["nan", "raise"] = "nan"
    ) -> NDArray[np.float64]:
        """Project 3D points in the camera frame to distorted pixels, (N, 3) -> (N, 2).

        Eq. 1 with ``[R | t] = [I | 0]``, then eqs. 3-5 and ``K`` (eq. 2).  Points at or behind
        the camera (z <= 0) have no image: they project to NaN (``behind="nan"``, convenient
        for batches) or raise ``ValueError`` naming them (``behind="raise"``).
        """
        if behind not in ("nan", "raise"):
            raise ValueError(f"behind must be 'nan' or 'raise', got {behind!r}")
        P = _check_points(points_cam, 3, "points_cam")
        z = P[:, 2]
        bad = z <= 0
        if behind == "raise" and np.any(bad):
            rows = np.flatnonzero(bad)
            raise ValueError(
                f"points_cam has {rows.size} point(s) at or behind the camera (z <= 0), "
                f"rows {rows[:5].tolist()}: first {P[rows[0]].tolist()}"
            )
        with np.errstate(divide="ignore", invalid="ignore"):
            xy = P[:, :2] / z[:, None]
        xy[bad] = 0.0
        uv = self.pixels_from_normalized(self.distort_normalized(xy))
        uv[bad] = np.nan
        return uv

    def project_world(
        self,
        points: ArrayLike,
        T_cam_world: ArrayLike,
        *,
        behind: Literal["nan", "raise"] = "nan",
    ) -> NDArray[np.float64]:
        """Project points given in another frame through ``T_cam_world`` (4x4), (N, 3) -> (N, 2).

        This is the full eq. 1, ``x = K [R | t] X``, with ``[R | t]`` the top rows of
        ``T_cam_world``; OpenCV's ``(rvec, tvec)`` become ``T_from_rvec_tvec(rvec, tvec)``.
        """
        P = _check_points(points, 3, "points")
        T = np.asarray(T_cam_world, dtype=np.float64)
        if T.shape != (4, 4):
            raise ValueError(f"T_cam_world must have shape (4, 4), got {T.shape}")
        if not np.all(np.isfinite(T)) or not np.allclose(T[3], [0.0, 0.0, 0.0, 1.0]):
            raise ValueError(f"T_cam_world must be a finite rigid transform, got {T.tolist()}")
        return self.project(P @ T[:3, :3].T + T[:3, 3], behind=behind)

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
        normalised coordinates as ``cv2.undistortPoints`` does (its iterative variant with a
        tight criterion; OpenCV's default five fixed-point steps stop short, up to 1e-3 off).
        """
        xy = self.undistort_normalized(self.normalized_from_pixels(uv))
        return self.pixels_from_normalized(xy) if to_pixels else xy

    def rays(self, uv: ArrayLike) -> NDArray[np.float64]:
        """Unit viewing rays in the camera frame for distorted pixels, (N, 2) -> (N, 3)."""
        xy = self.undistort_pixels(uv, to_pixels=False)
        r = np.concatenate([xy, np.ones((xy.shape[0], 1))], axis=1)
        return r / np.linalg.norm(r, axis=1, keepdims=True)

    # -- whole images --------------------------------------------------------------------
    def _pixel_grid(self) -> NDArray[np.float64]:
        vv, uu = np.mgrid[0 : self.height, 0 : self.width].astype(np.float64)
        return np.stack([uu.ravel(), vv.ravel()], axis=1)

    def undistort_maps(
        self,
        K_new: ArrayLike | None = None,
        *,
        R: ArrayLike | None = None,
        dtype: type[np.floating] = np.float32,
    ) -> tuple[NDArray[np.floating], NDArray[np.floating]]:
        """Maps for ``cv2.remap`` that turn a distorted image into an undistorted one.

        For each pixel of the output (a pinhole camera with ``K_new``, default ``K``, optionally
        rotated by the rectification ``R``) the maps give where to sample the distorted input:
        project the pixel's ray through the distortion (eqs. 3-5).  This is what
        ``cv2.initUndistortRectifyMap(K, dist, R, K_new, (width, height), CV_32FC1)`` computes
        (bit-identical in float32; ``dtype=np.float64`` keeps full precision).
        """
        Kn = self.K if K_new is None else check_K(K_new)
        out = PinholeCamera(Kn, None, width=self.width, height=self.height)
        xy = out.normalized_from_pixels(self._pixel_grid())
        if R is not None:
            Ra = np.asarray(R, dtype=np.float64)
            if Ra.shape != (3, 3) or not np.allclose(Ra @ Ra.T, np.eye(3), atol=1e-9):
                raise ValueError(f"R must be a 3x3 rotation matrix, got {Ra.tolist()}")
            # Output ray in the rectified frame -> ray in the camera frame: R^T (x, y, 1).
            ray = np.concatenate([xy, np.ones((xy.shape[0], 1))], axis=1) @ Ra
            with np.errstate(divide="ignore", invalid="ignore"):
                xy = ray[:, :2] / ray[:, 2:3]
            xy[ray[:, 2] <= 0] = np.nan  # rays turned away from the camera have no source
        good = np.all(np.isfinite(xy), axis=1)
        src = np.full_like(xy, np.nan)
        src[good] = self.pixels_from_normalized(self.distort_normalized(xy[good]))
        mx = src[:, 0].reshape(self.height, self.width).astype(dtype)
        my = src[:, 1].reshape(self.height, self.width).astype(dtype)
        return mx, my

    def distort_maps(
        self, K_ideal: ArrayLike | None = None
    ) -> tuple[NDArray[np.float32], NDArray[np.float32]]:
        """Maps for ``cv2.remap`` that turn an ideal pinhole image (``K_ideal``, default ``K``)
        into what this lens would record: each output pixel is undistorted (Newton inverse of
        eqs. 3-5) and sampled in the ideal image.  The simulator uses this on its renders.
        Pixels whose inverse does not exist (beyond the fold of an extreme lens) are NaN,
        which ``cv2.remap`` fills with the border value.
        """
        Ki = self.K if K_ideal is None else check_K(K_ideal)
        ideal = PinholeCamera(Ki, None, width=self.width, height=self.height)
        xy = self.undistort_pixels(self._pixel_grid(), to_pixels=False)
        good = np.all(np.isfinite(xy), axis=1)
        src = np.full_like(xy, np.nan)
        src[good] = ideal.pixels_from_normalized(xy[good])
        mx = src[:, 0].reshape(self.height, self.width).astype(np.float32)
        my = src[:, 1].reshape(self.height, self.width).astype(np.float32)
        return mx, my
