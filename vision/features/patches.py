"""Oriented, scale-normalised patches around keypoints, sampled with one ``cv2.remap`` per
pyramid level (shared by PCA-SIFT and GLOH), and the SIFT detector they both use."""

from __future__ import annotations

from collections.abc import Callable

import cv2
import numpy as np

from vision.features.opencv import keypoints_from_cv
from vision.features.pca import PcaBasis, default_basis
from vision.features.types import Features, Keypoints

__all__ = ["detect_sift", "patch_gradients", "sample_patches"]

_CHUNK = 400  # keypoints per remap call (keeps the stacked map well under 32k rows)


def detect_sift(
    grey: np.ndarray,
    *,
    max_features: int | None = None,
    threshold: float | None = None,
    mask: np.ndarray | None = None,
) -> tuple[Keypoints, list[cv2.KeyPoint]]:
    """DoG keypoints with orientation from OpenCV's SIFT detector (Lowe 2004).

    Returns the keypoints both as :class:`Keypoints` and as OpenCV's list (whose packed
    octave/layer field OpenCV's ``compute`` needs), strongest first when trimmed.
    """
    if threshold is not None and not threshold > 0:
        raise ValueError(f"threshold must be > 0, got {threshold!r}")
    if max_features is not None and max_features < 1:
        raise ValueError(f"max_features must be >= 1, got {max_features!r}")
    kw = {} if threshold is None else {"contrastThreshold": float(threshold)}
    det = cv2.SIFT_create(nfeatures=max_features or 0, **kw)  # type: ignore[attr-defined]
    m = None if mask is None else (np.asarray(mask) > 0).astype(np.uint8)
    kps = list(det.detect(grey, m))
    if max_features and len(kps) > max_features:
        order = np.argsort([-k.response for k in kps], kind="stable")[:max_features]
        kps = [kps[i] for i in order]
    return keypoints_from_cv(kps), kps


def sample_patches(
    image: np.ndarray, kp: Keypoints, *, size: int = 41, step_per_size: float = 0.15
) -> np.ndarray:
    """Square patches centred on keypoints, rotated to their orientation and scaled to their
    size.

    Patch sample ``(u, v)`` (column, row from the patch centre) lies at image position
    ``xy + step * (u * e_u + v * e_v)`` with ``e_u = (cos a, -sin a)`` (the keypoint's
    orientation ``a``, counter-clockwise on screen) and ``e_v = (sin a, cos a)``, and
    ``step = step_per_size * size_px``. To avoid aliasing, each keypoint is sampled from the
    level of a Gaussian pyramid (``cv2.pyrDown``) where the step is 1 to 2 pixels; all
    keypoints of a level are sampled by one bilinear ``cv2.remap`` on a stacked grid.

    Parameters
    ----------
    image : ndarray of shape (H, W)
        Grey image, any real dtype (converted to float32).
    kp : Keypoints
    size : int
        Patch side in samples (odd).
    step_per_size : float
        Sample spacing in units of the keypoint's ``size_px``.

    Returns
    -------
    ndarray of shape (N, size, size), float32
    """
    if size < 3 or size % 2 == 0:
        raise ValueError(f"size must be an odd integer >= 3, got {size!r}")
    if not step_per_size > 0:
        raise ValueError(f"step_per_size must be > 0, got {step_per_size!r}")
    img = np.asarray(image, dtype=np.float32)
    if img.ndim != 2:
        raise ValueError(f"image must have shape (H, W), got {img.shape}")
    n = len(kp)
    out = np.zeros((n, size, size), np.float32)
    if n == 0:
        return out
    step = step_per_size * kp.size_px
    max_level = max(0, int(np.log2(max(1, min(img.shape) // 8))))
    level = np.clip(np.floor(np.log2(np.maximum(step, 1.0))), 0, max_level).astype(int)
    half = (size - 1) / 2
    g = np.arange(size, dtype=np.float64) - half
    gu, gv = np.meshgrid(g, g)  # (size, size): column offsets, row offsets
    pyr = img
    for lev in range(int(level.max()) + 1):
        if lev > 0:
            pyr = np.asarray(cv2.pyrDown(pyr), dtype=pyr.dtype)
        idx = np.nonzero(level == lev)[0]
        if len(idx) == 0:
            continue
        src = cv2.GaussianBlur(pyr, (0, 0), 0.6) if lev > 0 else pyr
        f = 2.0**lev
        for c0 in range(0, len(idx), _CHUNK):
            sel = idx[c0 : c0 + _CHUNK]
            a = kp.angle_rad[sel][:, None, None]
            s = (step[sel] / f)[:, None, None]
            cx = (kp.xy[sel, 0][:, None, None] + 0.5) / f - 0.5
            cy = (kp.xy[sel, 1][:, None, None] + 0.5) / f - 0.5
            ca, sa = np.cos(a), np.sin(a)
            mx = cx + s * (gu * ca + gv * sa)
            my = cy + s * (-gu * sa + gv * ca)
            mx = mx.reshape(-1, size).astype(np.float32)
            my = my.reshape(-1, size).astype(np.float32)
            res = cv2.remap(src, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
            out[sel] = res.reshape(len(sel), size, size)
    return out


def patch_gradients(patches: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Central-difference gradients of the patches' interior: ``(gx, gy)``, each of shape
    ``(N, size - 2, size - 2)`` (``gx`` along the patch columns, ``gy`` along its rows)."""
    p = np.asarray(patches, dtype=np.float32)
    gx = p[:, 1:-1, 2:] - p[:, 1:-1, :-2]
    gy = p[:, 2:, 1:-1] - p[:, :-2, 1:-1]
    return gx, gy


def reduced_sift_features(
    grey: np.ndarray,
    kind: str,
    describe_raw: Callable[[np.ndarray, Keypoints], np.ndarray],
    dim_in: int,
    raw_version: str,
    *,
    max_features: int | None,
    threshold: float | None,
    mask: np.ndarray | None,
    basis: PcaBasis | None,
    reduce: bool,
) -> Features:
    """The common path of the PCA-reduced descriptors at DoG keypoints (PCA-SIFT, GLOH):
    check the basis, detect with OpenCV's SIFT detector, compute the raw ``dim_in`` vectors
    with ``describe_raw(grey, keypoints)`` and project them (equation 18) unless ``reduce``
    is False (then the version is ``raw_version``)."""
    if reduce:
        basis = basis if basis is not None else default_basis(kind)
        if basis.dim_in != dim_in:
            raise ValueError(f"basis must reduce {dim_in}-dim vectors, got {basis.dim_in}")
    kp, _ = detect_sift(grey, max_features=max_features, threshold=threshold, mask=mask)
    raw = describe_raw(grey, kp)
    if not reduce:
        return Features(kp, raw, kind, raw_version, False, grey.shape[:2])
    assert basis is not None  # set above whenever reduce is true
    return Features(kp, basis.project(raw), kind, basis.version, False, grey.shape[:2])
