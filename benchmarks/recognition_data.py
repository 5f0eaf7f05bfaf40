"""COIL-20 images for the recognition benchmark, and the two baselines measured beside the
view index: brute-force registration against every trained view, and the parametric
eigenspace of Murase and Nayar (IJCV 14, 1995).

COIL-20 (Nene, Nayar and Murase, "Columbia Object Image Library (COIL-20)", CUCS-005-96,
1996): objects on a turntable photographed every 5 degrees, 72 views each, 128x128 grey; file
``obj<O>__<K>.png`` shows object ``O`` at ``5 * K`` degrees. Objects 1..15 are in the shared
data folder.
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from vision.features import Features
from vision.registration import register

N_VIEWS = 72
STEP_DEG = 5


def coil_folder(data_dir: Path) -> Path:
    """The COIL-20 folder, or ``FileNotFoundError`` naming it."""
    folder = Path(data_dir) / "recognition" / "coil20"
    if not (folder / "obj1__0.png").is_file():
        raise FileNotFoundError(f"COIL-20 images are absent from {folder} (see the data README)")
    return folder


def load_coil(folder: Path, objects: range) -> dict[tuple[int, int], np.ndarray]:
    """Every view ``(object, k)`` of ``objects`` as grey uint8 (128, 128)."""
    out = {}
    for o in objects:
        for k in range(N_VIEWS):
            img = cv2.imread(str(folder / f"obj{o}__{k}.png"), cv2.IMREAD_GRAYSCALE)
            if img is None:
                raise FileNotFoundError(f"missing COIL-20 image obj{o}__{k}.png in {folder}")
            out[(o, k)] = img
    return out


def rotate(image: np.ndarray, angle_deg: float, scale: float = 1.0) -> np.ndarray:
    """In-plane rotation about the centre (COIL's black background fills the corners)."""
    h, w = image.shape[:2]
    M = cv2.getRotationMatrix2D((w / 2.0, h / 2.0), angle_deg, scale)
    return cv2.warpAffine(image, M, (w, h), flags=cv2.INTER_LINEAR, borderValue=0)


def brute_force(
    trained: list[tuple[str, Features]], query: Features, *, geometry: str
) -> dict[str, float]:
    """Score of every model as the best registration score over *all* its trained views:
    what the chapter's VisionServer does per model (section 3.5.1), one registration each."""
    scores: dict[str, float] = {}
    for model, f in trained:
        s = 0.0 if len(query) < 3 else register(f, query, model=geometry).score
        scores[model] = max(scores.get(model, 0.0), s)
    return scores


class Eigenspace:
    """Murase and Nayar's parametric eigenspace, with nearest-neighbour recognition.

    Each image is normalised for brightness (unit L2 norm of its pixel vector, as in Murase
    and Nayar 1995, section 3), the training set's mean is removed and its leading
    ``n_components`` principal directions (the "universal eigenspace") are kept; a query is
    projected and takes the model of the nearest projected training image. (The paper
    interpolates the projected views by a cubic spline into a manifold; with 10-30 degree
    training steps the nearest sample is what the issue asks for as the baseline.)
    """

    def __init__(self, images: list[np.ndarray], labels: list[str], *, n_components: int = 20):
        X = self._vectors(images)
        self.mean = X.mean(axis=0)
        _, _, vt = np.linalg.svd(X - self.mean, full_matrices=False)
        self.basis = vt[: min(n_components, len(vt))]
        self.points = (X - self.mean) @ self.basis.T
        self.labels = list(labels)

    @staticmethod
    def _vectors(images: list[np.ndarray]) -> np.ndarray:
        X = np.stack([np.asarray(i, np.float64).reshape(-1) for i in images])
        return X / np.maximum(np.linalg.norm(X, axis=1, keepdims=True), 1e-12)

    def predict(self, image: np.ndarray) -> str:
        """Model of the nearest training image in the eigenspace."""
        p = (self._vectors([image]) - self.mean) @ self.basis.T
        return self.labels[int(np.argmin(((self.points - p) ** 2).sum(axis=1)))]
