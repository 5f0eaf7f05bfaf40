"""Reading calibration inputs: image folders, robot pose files, intrinsics files."""

from __future__ import annotations

import json
import re
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from vision.camera import PinholeCamera, check_dist, check_K
from vision.errors import ImageError
from vision.sources import IMAGE_SUFFIXES

__all__ = ["list_images", "parse_poses", "read_gray", "read_intrinsics", "read_poses"]


def _natural_key(p: Path) -> list[Any]:
    return [int(s) if s.isdigit() else s.lower() for s in re.split(r"(\d+)", p.name)]


def list_images(folder: str | Path) -> list[Path]:
    """Image files of ``folder`` in natural order (``im_2`` before ``im_10``)."""
    d = Path(folder)
    if not d.is_dir():
        raise ValueError(f"images must be a folder, got {str(folder)!r}")
    return sorted(
        (p for p in d.iterdir() if p.is_file() and p.suffix.lower() in IMAGE_SUFFIXES),
        key=_natural_key,
    )


def read_gray(path: str | Path) -> NDArray[np.uint8]:
    """Read an image file as greyscale uint8 (H, W)."""
    img = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
    if img is None:
        raise ImageError(f"cannot read image {str(path)!r}")
    return np.asarray(img, dtype=np.uint8)


def parse_poses(text: str, *, unit_m: float = 1.0, source: str = "poses") -> NDArray[np.float64]:
    """Robot poses from text: one pose per line, 16 numbers (a row-major 4x4 ``T_base_ee``)
    or 12 (its top 3x4), separated by spaces, tabs or commas; ``#`` starts a comment.

    ``unit_m`` scales the translations to metres (0.001 for files in millimetres).
    """
    poses = []
    for k, raw in enumerate(text.splitlines(), start=1):
        line = raw.split("#", 1)[0].strip()
        if not line:
            continue
        try:
            vals = [float(v) for v in re.split(r"[\s,;]+", line) if v]
        except ValueError:
            raise ValueError(
                f"{source} line {k}: expected numbers, got {raw.strip()[:60]!r}"
            ) from None
        if len(vals) not in (12, 16):
            raise ValueError(
                f"{source} line {k}: expected 16 numbers (a row-major 4x4 pose) or 12 (3x4), "
                f"got {len(vals)}"
            )
        T = np.eye(4)
        T[: len(vals) // 4] = np.reshape(vals, (-1, 4))
        T[:3, 3] *= unit_m
        poses.append(T)
    if not poses:
        raise ValueError(f"{source}: no poses found")
    return np.array(poses)


def read_poses(path: str | Path, *, unit_m: float = 1.0) -> NDArray[np.float64]:
    """:func:`parse_poses` on a file (e.g. ``RobotPosesVec.txt``)."""
    p = Path(path)
    if not p.is_file():
        raise ValueError(f"poses must be a file, got {str(path)!r}")
    return parse_poses(p.read_text(), unit_m=unit_m, source=p.name)


def read_intrinsics(path: str | Path) -> PinholeCamera:
    """Intrinsics from a JSON file (written by ``visioncell calibrate intrinsics --save``:
    keys ``K``, ``dist``, ``image_size``) or an OpenCV YAML/XML file (``camera_matrix``,
    ``distortion_coefficients``, ``image_width``, ``image_height``)."""
    p = Path(path)
    if not p.is_file():
        raise ValueError(f"intrinsics must be a file, got {str(path)!r}")
    if p.suffix.lower() == ".json":
        try:
            d = json.loads(p.read_text())
            K, dist = d["K"], d["dist"]
            w, h = d.get("image_size", (640, 480))
        except (json.JSONDecodeError, KeyError, TypeError, ValueError) as exc:
            raise ValueError(
                f"intrinsics file {p.name!r} is not a VisionCell intrinsics JSON: {exc}"
            ) from None
    else:
        try:
            fs = cv2.FileStorage(str(p), cv2.FILE_STORAGE_READ)
        except cv2.error as exc:
            raise ValueError(
                f"intrinsics file {p.name!r} is not OpenCV YAML/XML: {exc.err}"
            ) from None
        try:
            Kn, dn = fs.getNode("camera_matrix"), fs.getNode("distortion_coefficients")
            if Kn.empty() or dn.empty():
                raise ValueError(
                    f"intrinsics file {p.name!r} needs camera_matrix and distortion_coefficients"
                )
            K, dist = Kn.mat(), dn.mat().ravel()[:5]
            wn, hn = fs.getNode("image_width"), fs.getNode("image_height")
            w = int(wn.real()) if not wn.empty() else 640
            h = int(hn.real()) if not hn.empty() else 480
        finally:
            fs.release()
    return PinholeCamera(check_K(K), check_dist(dist), width=int(w), height=int(h))
