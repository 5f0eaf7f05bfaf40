"""Value types of the feature layer: keypoints and the descriptors extracted at them."""

from __future__ import annotations

import io
from dataclasses import dataclass, field
from typing import Any

import numpy as np

__all__ = ["Features", "Keypoints"]


def _frozen(a: np.ndarray) -> np.ndarray:
    a.setflags(write=False)
    return a


@dataclass(frozen=True, eq=False)
class Keypoints:
    """Interest points in pixel coordinates of the image they were found in.

    Attributes
    ----------
    xy : ndarray of shape (N, 2), float64
        ``(x, y)`` = (column, row) in pixels, OpenCV's sub-pixel convention (pixel centres at
        integers).
    size_px : ndarray of shape (N,), float64
        Diameter of the measurement region in pixels (OpenCV's ``KeyPoint.size``).
    angle_rad : ndarray of shape (N,), float64
        Dominant orientation in radians, counter-clockwise in the image as displayed
        (``-KeyPoint.angle`` converted: OpenCV measures degrees clockwise because y points down).
        0 for upright descriptors.
    response : ndarray of shape (N,), float64
        Detector strength (DoG or Hessian determinant); larger is stronger.
    octave : ndarray of shape (N,), int32
        Pyramid octave the point was detected in (method-specific, 0 = finest).
    shape : ndarray of shape (N, 2, 2) or None
        For affine-covariant detectors, the second-moment shape matrix ``M`` such that the
        region is ``{x : (x - xy)^T M (x - xy) <= 1}``; ``None`` for similarity-covariant ones.
    """

    xy: np.ndarray
    size_px: np.ndarray
    angle_rad: np.ndarray
    response: np.ndarray
    octave: np.ndarray
    shape: np.ndarray | None = None

    def __post_init__(self) -> None:
        n = len(self.xy)
        xy = np.asarray(self.xy, dtype=np.float64).reshape(n, 2)
        cols: dict[str, np.ndarray] = {
            "size_px": np.asarray(self.size_px, dtype=np.float64).reshape(-1),
            "angle_rad": np.asarray(self.angle_rad, dtype=np.float64).reshape(-1),
            "response": np.asarray(self.response, dtype=np.float64).reshape(-1),
            "octave": np.asarray(self.octave, dtype=np.int32).reshape(-1),
        }
        for name, col in cols.items():
            if len(col) != n:
                raise ValueError(f"Keypoints.{name} has {len(col)} entries, xy has {n}")
            object.__setattr__(self, name, _frozen(col))
        object.__setattr__(self, "xy", _frozen(xy))
        if self.shape is not None:
            shape = np.asarray(self.shape, dtype=np.float64)
            if shape.shape != (n, 2, 2):
                raise ValueError(f"Keypoints.shape must be ({n}, 2, 2), got {shape.shape}")
            object.__setattr__(self, "shape", _frozen(shape))

    def __len__(self) -> int:
        return len(self.xy)

    @classmethod
    def empty(cls) -> Keypoints:
        """No keypoints."""
        z = np.zeros(0)
        return cls(np.zeros((0, 2)), z, z, z, np.zeros(0, dtype=np.int32))

    def take(self, index: np.ndarray) -> Keypoints:
        """The keypoints selected by an integer or boolean index."""
        return Keypoints(
            self.xy[index],
            self.size_px[index],
            self.angle_rad[index],
            self.response[index],
            self.octave[index],
            None if self.shape is None else self.shape[index],
        )


@dataclass(frozen=True, eq=False)
class Features:
    """Keypoints and their descriptors, as returned by :func:`vision.features.extract`.

    Attributes
    ----------
    keypoints : Keypoints
        N interest points.
    descriptors : ndarray of shape (N, D)
        float32 for real-valued descriptors (compare with L2), uint8 packed bits for binary
        ones (ORB, AKAZE's MLDB; compare with Hamming), see ``binary``.
    method : str
        Method id as given to ``extract`` (``"sift"``, ``"surf"``, ``"color-surf"``, ...).
    version : str
        Version of the descriptor: it changes whenever stored descriptors of the same method
        stop being comparable with new ones (another PCA basis, another layout).
    binary : bool
        True when ``descriptors`` are packed bits compared by Hamming distance.
    image_shape : tuple of int
        ``(height, width)`` of the image the features come from.
    """

    keypoints: Keypoints
    descriptors: np.ndarray
    method: str
    version: str
    binary: bool = False
    image_shape: tuple[int, int] = field(default=(0, 0))

    def __post_init__(self) -> None:
        d = np.asarray(self.descriptors)
        if d.ndim != 2 or len(d) != len(self.keypoints):
            raise ValueError(
                f"descriptors must have shape ({len(self.keypoints)}, D), got {d.shape}"
            )
        want = np.uint8 if self.binary else np.float32
        d = np.ascontiguousarray(d, dtype=want)
        object.__setattr__(self, "descriptors", _frozen(d))
        object.__setattr__(self, "image_shape", tuple(int(v) for v in self.image_shape))

    def __len__(self) -> int:
        return len(self.keypoints)

    @property
    def dim(self) -> int:
        """Descriptor length (bytes for binary descriptors)."""
        return int(self.descriptors.shape[1])

    def take(self, index: np.ndarray) -> Features:
        """The features selected by an integer or boolean index."""
        return Features(
            self.keypoints.take(index),
            self.descriptors[index],
            self.method,
            self.version,
            self.binary,
            self.image_shape,
        )

    def to_bytes(self) -> bytes:
        """Serialise to a compressed ``.npz`` blob (the database's feature column)."""
        buf = io.BytesIO()
        kp = self.keypoints
        extra: dict[str, Any] = {} if kp.shape is None else {"shape": kp.shape}
        np.savez_compressed(
            buf,
            xy=kp.xy,
            size_px=kp.size_px,
            angle_rad=kp.angle_rad,
            response=kp.response,
            octave=kp.octave,
            descriptors=self.descriptors,
            meta=np.array([self.method, self.version, str(int(self.binary))]),
            image_shape=np.array(self.image_shape, dtype=np.int64),
            **extra,
        )
        return buf.getvalue()

    @classmethod
    def from_bytes(cls, blob: bytes) -> Features:
        """Inverse of :meth:`to_bytes`; raises ``ValueError`` on a blob that is not one."""
        try:
            with np.load(io.BytesIO(blob), allow_pickle=False) as z:
                method, version, binary = (str(v) for v in z["meta"])
                kp = Keypoints(
                    z["xy"],
                    z["size_px"],
                    z["angle_rad"],
                    z["response"],
                    z["octave"],
                    z["shape"] if "shape" in z.files else None,
                )
                return cls(
                    kp,
                    z["descriptors"],
                    method,
                    version,
                    binary == "1",
                    (int(z["image_shape"][0]), int(z["image_shape"][1])),
                )
        except (OSError, KeyError, ValueError) as exc:
            raise ValueError(f"not a serialised Features blob: {exc}") from exc
