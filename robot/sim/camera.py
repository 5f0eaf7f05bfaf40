"""The eye-in-hand camera of the simulated cell: mounting, lens, sensor and motion blur.

The camera is a CCD on the flange (chapter section 4.1).  Its ground truth:

* mounting ``T_ee_cam`` (:data:`DEFAULT_T_EE_CAM`): the optical centre sits 50 mm from the
  approach axis along ``x_ee`` and 40 mm past the flange face; the optical axis is the
  approach axis tilted by 3 deg about ``x_cam`` and 1 deg about ``y_cam``.  Image x runs
  along ``y_ee`` and image y along ``-x_ee``: with the tool pointing down at the station
  and ``q1 = q5 = 0`` the belt crosses the image from left to right, the arm's side at the top;
* intrinsics from the field of view: square pixels, ``f = (H / 2) / tan(fovy / 2)`` with
  MuJoCo's vertical ``fovy``, principal point at the image centre ``((W-1)/2, (H-1)/2)``
  (pixel centres at integers, as in :mod:`vision.camera`);
* lens distortion (chapter eqs. 3-5, ``dist = (k1, k2, p1, p2, k3)``) applied to the ideal
  pinhole render with :meth:`vision.camera.PinholeCamera.distort_maps`, the same code the
  vision side uses.  The ideal render covers a slightly larger canvas (same ``f``) so that
  every distorted pixel has a source.

Sensor effects, all optional: brightness ``gain * exposure_s / reference_exposure_s``,
Gaussian read noise plus shot noise, and motion blur from the arm's joint speeds during the
exposure (the ideal image is warped along the optical flow of the camera's own motion, using
the render's depth, and averaged over the exposure).  Objects moving on the belt are not
blurred (their speed is small next to the arm's).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from functools import cached_property

import cv2
import numpy as np
from numpy.typing import ArrayLike, NDArray

from robot.kinematics import T_base_ee
from robot.model import ASEA, ArmModel
from vision.camera import PinholeCamera, check_dist

__all__ = [
    "DEFAULT_DIST",
    "DEFAULT_T_EE_CAM",
    "CameraSpec",
    "Lens",
    "Sensor",
    "exposure_end_poses",
    "motion_blur",
]


def _rot(axis: str, a: float) -> NDArray[np.float64]:
    c, s = math.cos(a), math.sin(a)
    if axis == "x":
        return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])
    return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])


def _default_mount() -> NDArray[np.float64]:
    # Columns of R_ee_cam before the tilt: x_cam = y_ee, y_cam = -x_ee, z_cam = z_ee.
    R0 = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    T = np.eye(4)
    T[:3, :3] = R0 @ _rot("x", math.radians(3.0)) @ _rot("y", math.radians(1.0))
    T[:3, 3] = (0.05, 0.0, 0.04)
    T.setflags(write=False)
    return T


#: True mounting of the camera on the flange (``T_ee_cam``, OpenCV camera frame).
DEFAULT_T_EE_CAM = _default_mount()
#: Default lens: moderate barrel distortion of a 6-8 mm machine-vision lens.
DEFAULT_DIST = (-0.12, 0.03, 0.0008, -0.0005, 0.0)


@dataclass(frozen=True)
class CameraSpec:
    """The simulated camera.

    Attributes
    ----------
    width, height : int
        Image size, pixels.
    fovy_deg : float
        Vertical field of view of the undistorted pinhole, degrees.
    dist : tuple of 5 floats
        ``(k1, k2, p1, p2, k3)``; all zeros for an ideal lens.
    T_ee_cam : ndarray of shape (4, 4)
        Mounting on the flange.
    noise_std_dn : float
        Read noise, grey levels (0 for none); shot noise adds ``sqrt(0.02 * level)``.
    exposure_s : float
        Exposure time (motion blur integrates the arm's motion over it).
    reference_exposure_s : float
        Exposure at which the brightness is the render's own.
    gain : float
        Brightness multiplier.
    motion_blur : bool
        Blur with the camera's motion during the exposure.
    seed : int
        Seed of the noise generator.
    """

    width: int = 640
    height: int = 480
    fovy_deg: float = 58.0
    dist: tuple[float, ...] = DEFAULT_DIST
    T_ee_cam: NDArray[np.float64] = field(default_factory=lambda: DEFAULT_T_EE_CAM)
    noise_std_dn: float = 1.5
    exposure_s: float = 0.008
    reference_exposure_s: float = 0.008
    gain: float = 1.0
    motion_blur: bool = True
    seed: int = 0

    def __post_init__(self) -> None:
        if self.width < 16 or self.height < 16:
            raise ValueError(f"image size must be at least 16x16, got {self.width}x{self.height}")
        if not 5.0 <= self.fovy_deg <= 120.0:
            raise ValueError(f"fovy_deg must be in [5, 120], got {self.fovy_deg!r}")
        d = check_dist(self.dist)
        object.__setattr__(self, "dist", tuple(float(v) for v in d))
        T = np.asarray(self.T_ee_cam, dtype=np.float64)
        if T.shape != (4, 4) or not np.allclose(T[:3, :3] @ T[:3, :3].T, np.eye(3), atol=1e-9):
            raise ValueError(f"T_ee_cam must be a 4x4 rigid transform, got {T.tolist()}")
        T = T.copy()
        T.setflags(write=False)
        object.__setattr__(self, "T_ee_cam", T)
        if self.noise_std_dn < 0 or not math.isfinite(self.noise_std_dn):
            raise ValueError(f"noise_std_dn must be >= 0, got {self.noise_std_dn!r}")
        if not self.exposure_s > 0 or not self.reference_exposure_s > 0:
            raise ValueError(
                f"exposure_s and reference_exposure_s must be positive, got {self.exposure_s!r}, "
                f"{self.reference_exposure_s!r}"
            )
        if not 0.0 < self.gain <= 16.0:
            raise ValueError(f"gain must be in (0, 16], got {self.gain!r}")

    def with_(self, **changes: object) -> CameraSpec:
        """A copy with some fields changed (validated)."""
        return replace(self, **changes)  # type: ignore[arg-type]

    @property
    def focal_px(self) -> float:
        """Focal length in pixels from the vertical field of view."""
        return 0.5 * self.height / math.tan(math.radians(self.fovy_deg) / 2.0)

    @property
    def K(self) -> NDArray[np.float64]:
        """True intrinsic matrix (chapter eq. 2)."""
        f = self.focal_px
        return np.array(
            [[f, 0.0, (self.width - 1) / 2.0], [0.0, f, (self.height - 1) / 2.0], [0.0, 0.0, 1.0]]
        )

    @property
    def pinhole(self) -> PinholeCamera:
        """The true camera model (``K``, ``dist``, size) as :class:`vision.camera.PinholeCamera`."""
        return PinholeCamera(self.K, self.dist, width=self.width, height=self.height)

    def T_base_cam(self, q: ArrayLike, model: ArmModel = ASEA) -> NDArray[np.float64]:
        """True camera pose for joints ``q``: ``T_base_ee(q) @ T_ee_cam``."""
        return T_base_ee(q, model) @ self.T_ee_cam


class Lens:
    """The ideal render canvas and the distortion maps of one :class:`CameraSpec`.

    The ideal canvas has the camera's focal length and a centred principal point, and is
    large enough that every output pixel's undistorted ray falls inside it (one pixel of
    margin for bilinear interpolation).
    """

    def __init__(self, spec: CameraSpec) -> None:
        self.spec = spec
        cam = spec.pinhole
        W, H = spec.width, spec.height
        border = np.concatenate(
            [
                np.stack([np.arange(W), np.zeros(W)], 1),
                np.stack([np.arange(W), np.full(W, H - 1)], 1),
                np.stack([np.zeros(H), np.arange(H)], 1),
                np.stack([np.full(H, W - 1), np.arange(H)], 1),
            ]
        ).astype(np.float64)
        xy = cam.undistort_pixels(border, to_pixels=False)
        f = spec.focal_px
        half_w = max(float(np.abs(xy[:, 0]).max()) * f, (W - 1) / 2.0) + 2.0
        half_h = max(float(np.abs(xy[:, 1]).max()) * f, (H - 1) / 2.0) + 2.0
        self.ideal_width = math.ceil(half_w) * 2 + 1
        self.ideal_height = math.ceil(half_h) * 2 + 1
        self.K_ideal = np.array(
            [
                [f, 0.0, (self.ideal_width - 1) / 2.0],
                [0.0, f, (self.ideal_height - 1) / 2.0],
                [0.0, 0.0, 1.0],
            ]
        )
        #: MuJoCo's vertical field of view for the ideal canvas, degrees.
        self.ideal_fovy_deg = math.degrees(2.0 * math.atan(0.5 * self.ideal_height / f))

    @cached_property
    def maps(self) -> tuple[NDArray[np.int16], NDArray[np.uint16]]:
        """Fixed-point ``cv2.remap`` maps from the ideal canvas to the distorted image."""
        mx, my = self.spec.pinhole.distort_maps(self.K_ideal)
        m1, m2 = cv2.convertMaps(mx, my, cv2.CV_16SC2)
        return np.asarray(m1, dtype=np.int16), np.asarray(m2, dtype=np.uint16)

    @cached_property
    def nearest_maps(self) -> tuple[NDArray[np.float32], NDArray[np.float32]]:
        """Float ``cv2.remap`` maps from the ideal canvas to the distorted image (for labels)."""
        return self.spec.pinhole.distort_maps(self.K_ideal)

    def distort_labels(self, ideal: NDArray[np.int32]) -> NDArray[np.int32]:
        """A label image (e.g. geom ids) as the lens maps it, nearest ideal pixel per pixel.

        Labels must be below 2**24 (they pass through float32 exactly).
        """
        if ideal.shape != (self.ideal_height, self.ideal_width):
            raise ValueError(
                f"label image must be {self.ideal_height}x{self.ideal_width}, got {ideal.shape}"
            )
        mx, my = self.nearest_maps
        out = cv2.remap(
            ideal.astype(np.float32), mx, my, cv2.INTER_NEAREST, borderMode=cv2.BORDER_REPLICATE
        )
        return np.asarray(out).astype(np.int32)

    def distort(self, ideal: NDArray[np.uint8]) -> NDArray[np.uint8]:
        """The image the lens records from an ideal render of the canvas."""
        if ideal.shape[:2] != (self.ideal_height, self.ideal_width):
            raise ValueError(
                f"ideal image must be {self.ideal_height}x{self.ideal_width}, got {ideal.shape[:2]}"
            )
        m1, m2 = self.maps
        out = cv2.remap(ideal, m1, m2, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
        return np.asarray(out, dtype=np.uint8)


class Sensor:
    """Exposure, gain and noise of the image sensor.

    Brightness scales by ``gain * exposure_s / reference_exposure_s`` (saturating); the
    noise of a pixel at level ``I`` has standard deviation ``sqrt(read^2 + 0.02 I)`` (read
    noise plus shot noise).  Normal deviates come from a buffer drawn once from the seeded
    generator and read at a random offset per frame, which keeps a frame's noise cheap.
    """

    _BUFFER_FRAMES = 3

    def __init__(self, spec: CameraSpec) -> None:
        self._rng = np.random.default_rng(spec.seed)
        self._size = spec.width * spec.height * 3
        self._normal: NDArray[np.float32] | None = None
        self._lut_for: float | None = None
        self._lut = np.zeros((1, 256), np.float32)

    def apply(self, image: NDArray[np.uint8], spec: CameraSpec) -> NDArray[np.uint8]:
        """The recorded image for the ideal exposure ``image`` (uint8, H x W x 3)."""
        scale = spec.gain * spec.exposure_s / spec.reference_exposure_s
        img = (
            image
            if abs(scale - 1.0) < 1e-9
            else np.asarray(cv2.convertScaleAbs(image, alpha=scale), dtype=np.uint8)
        )
        if spec.noise_std_dn <= 0:
            return img
        if img.size != self._size:
            raise ValueError(f"image has {img.size} values, the sensor {self._size}")
        if self._normal is None:
            self._normal = self._rng.standard_normal(
                self._size * self._BUFFER_FRAMES, dtype=np.float32
            )
        if self._lut_for != spec.noise_std_dn:
            levels = np.arange(256, dtype=np.float32)
            self._lut = np.sqrt(spec.noise_std_dn**2 + 0.02 * levels)[None, :].astype(np.float32)
            self._lut_for = spec.noise_std_dn
        off = int(self._rng.integers(0, self._normal.size - self._size))
        n = self._normal[off : off + self._size].reshape(img.shape)
        sigma = cv2.LUT(img, self._lut)
        out = cv2.add(img.astype(np.float32), cv2.multiply(n, sigma))
        np.clip(out, 0.0, 255.0, out=out)
        return (out + 0.5).astype(np.uint8)


def motion_blur(
    ideal: NDArray[np.uint8],
    depth_m: NDArray[np.float32],
    K_ideal: NDArray[np.float64],
    T_start_mid: NDArray[np.float64],
    T_end_mid: NDArray[np.float64],
    *,
    min_flow_px: float = 0.3,
    px_per_sample: float = 1.5,
    max_samples: int = 9,
) -> NDArray[np.uint8]:
    """Average the ideal image over the exposure, warped along the camera's own flow.

    Parameters
    ----------
    ideal : ndarray (H, W, 3) uint8
        Render at the middle of the exposure.
    depth_m : ndarray (H, W) float32
        Distance along the optical axis per pixel.
    K_ideal : ndarray (3, 3)
        Intrinsics of the ideal render.
    T_start_mid, T_end_mid : ndarray (4, 4)
        Pose of the middle camera in the cameras at the start and the end of the exposure.
    min_flow_px : float
        Below this largest displacement the image is returned unchanged.
    px_per_sample : float
        Spacing of the sub-exposures along the largest flow (their number follows).

    Each pixel's 3D point ``P = depth * K^-1 (u, v, 1)`` is moved into the start and end
    cameras and projected, which gives the flow to either end of the exposure; in between
    the flow is taken as linear in time (an exposure is short).  The image seen at each
    sub-exposure is approximated to first order by sampling the middle image at
    ``u - flow(u)`` (backward warp), and the average of those is the blurred exposure.
    """
    H, W = depth_m.shape
    fx, fy, cx, cy = (
        np.float32(v) for v in (K_ideal[0, 0], K_ideal[1, 1], K_ideal[0, 2], K_ideal[1, 2])
    )
    step = 8  # the flow is smooth: compute it on a coarse grid, then resize
    vv, uu = np.mgrid[0:H:step, 0:W:step].astype(np.float32)
    z = depth_m[::step, ::step].astype(np.float32)
    X = (uu - cx) / fx * z
    Y = (vv - cy) / fy * z
    ends = []
    for T in (T_start_mid, T_end_mid):
        R, t = T[:3, :3].astype(np.float32), T[:3, 3].astype(np.float32)
        Xk = R[0, 0] * X + R[0, 1] * Y + R[0, 2] * z + t[0]
        Yk = R[1, 0] * X + R[1, 1] * Y + R[1, 2] * z + t[1]
        Zk = np.maximum(R[2, 0] * X + R[2, 1] * Y + R[2, 2] * z + t[2], np.float32(1e-3))
        fu = cv2.resize(
            (fx * Xk / Zk + cx - uu).astype(np.float32), (W, H), interpolation=cv2.INTER_LINEAR
        )
        fv = cv2.resize(
            (fy * Yk / Zk + cy - vv).astype(np.float32), (W, H), interpolation=cv2.INTER_LINEAR
        )
        ends.append((fu, fv))
    biggest = max(float(np.sqrt(fu * fu + fv * fv).max()) for fu, fv in ends)
    if biggest < min_flow_px:
        return ideal
    n = int(min(max_samples, max(3, math.ceil(2.0 * biggest / px_per_sample) + 1)))
    gu, gv = np.meshgrid(np.arange(W, dtype=np.float32), np.arange(H, dtype=np.float32))
    acc = np.zeros(ideal.shape, np.float32)
    for alpha in np.linspace(-1.0, 1.0, n):
        fu, fv = ends[0] if alpha < 0 else ends[1]
        a = np.float32(abs(alpha))
        acc += cv2.remap(
            ideal, gu - a * fu, gv - a * fv, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE
        )
    return np.clip(acc / n + 0.5, 0, 255).astype(np.uint8)


def exposure_end_poses(
    spec: CameraSpec, q: ArrayLike, qd: ArrayLike, *, model: ArmModel = ASEA
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """``(T_cam_start_cam_mid, T_cam_end_cam_mid)`` for joints ``q`` moving at ``qd`` during
    the exposure (joint speeds taken as constant over it)."""
    qa = np.asarray(q, dtype=np.float64)
    qda = np.asarray(qd, dtype=np.float64)
    T_mid = spec.T_base_cam(qa, model)
    half = 0.5 * spec.exposure_s
    T_start = spec.T_base_cam(qa - qda * half, model)
    T_end = spec.T_base_cam(qa + qda * half, model)
    return np.linalg.inv(T_start) @ T_mid, np.linalg.inv(T_end) @ T_mid
