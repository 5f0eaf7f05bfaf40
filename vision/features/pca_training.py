"""Training of the shipped PCA bases (chapter section 3.4.2: about 20,000 patches, the
covariance of equation 19, the projection of equation 18).

Pure vision code: the caller (``visioncell train-pca`` in :mod:`backend.cli.features`)
gathers the RGB training images and their names; this module computes the unreduced
descriptors at the keypoints of each image, samples the training set reproducibly and fits
the basis with its provenance.
"""

from __future__ import annotations

import datetime as _dt
from collections.abc import Callable, Sequence

import cv2
import numpy as np

from vision.features.extract import extract
from vision.features.pca import BASIS_KINDS, PcaBasis, fit_pca

#: Length of the grey block that leads the joint colour descriptors (kept whole, not reduced).
JOINT_GREY_DIMS = {"color-sift": 128, "color-surf": 64}

__all__ = [
    "raw_descriptors",
    "sample_training_set",
    "train_basis",
    "unavailable_reason",
]

Progress = Callable[[str, int, int], None]


def unavailable_reason(kind: str) -> str | None:
    """Why the descriptor ``kind`` cannot be computed here, or None when it can."""
    if kind not in BASIS_KINDS:
        return f"unknown kind {kind!r}; choose one of {', '.join(BASIS_KINDS)}"
    return None


def raw_descriptors(kind: str, rgb: np.ndarray, *, max_features: int = 3000) -> np.ndarray:
    """Unreduced descriptors of one RGB image at its own keypoints.

    Parameters
    ----------
    kind : str
        ``"pca-sift"`` (3042-dim gradient patches), ``"gloh"`` (272), ``"color-sift"`` (256)
        or ``"color-surf"`` (128): the colour blocks of their default (joint) layout, which
        follow the grey block (the basis reduces only them), ``"color-sift-chapter"``
        (384) or ``"color-surf-chapter"`` (192) in the chapter's layout.
    rgb : ndarray of shape (H, W, 3), uint8
    max_features : int
        Strongest keypoints kept per image.

    Returns
    -------
    ndarray of shape (N, D), float32
    """
    why = unavailable_reason(kind)
    if why is not None:
        raise ValueError(f"cannot compute {kind!r} descriptors: {why}")
    rgb = np.asarray(rgb)
    if rgb.dtype != np.uint8 or rgb.ndim != 3 or rgb.shape[2] != 3:
        raise ValueError(f"rgb must be a uint8 (H, W, 3) image, got {rgb.dtype} {rgb.shape}")
    method, opts = kind, {}
    if kind.endswith("-chapter"):  # the chapter's layout of the colour descriptor
        method, opts = kind.removesuffix("-chapter"), {"layout": "chapter"}
    d = extract(rgb, method, max_features=max_features, reduce=False, **opts).descriptors
    if kind in JOINT_GREY_DIMS:  # joint layout: the basis reduces the colour blocks only,
        d = d[:, JOINT_GREY_DIMS[kind] :]  # from the keypoints where colour has signal
        d = d[np.any(d != 0, axis=1)]
    return d


def sample_training_set(
    kind: str,
    images: Sequence[tuple[str, np.ndarray]],
    *,
    n_patches: int = 20000,
    seed: int = 0,
    max_features: int = 3000,
    progress: Progress | None = None,
) -> tuple[np.ndarray, dict[str, int]]:
    """Raw descriptors of ``kind`` from every image, sampled down to ``n_patches``.

    Each image contributes at most ``ceil(3 n_patches / n_images)`` descriptors (drawn at
    random, so no single large image dominates), then ``n_patches`` are drawn from the pool
    without replacement (all of them if the pool is smaller).

    Returns
    -------
    samples : ndarray of shape (n, D), float32
    counts : dict
        Source name -> number of its descriptors in ``samples``.
    """
    if not images:
        raise ValueError("images must name at least one (name, rgb) pair, got none")
    if n_patches < 2:
        raise ValueError(f"n_patches must be >= 2, got {n_patches!r}")
    rng = np.random.default_rng(seed)
    quota = int(np.ceil(3 * n_patches / len(images)))
    chunks, owners = [], []
    for i, (name, rgb) in enumerate(images):
        d = raw_descriptors(kind, rgb, max_features=max_features)
        if len(d) > quota:
            d = d[np.sort(rng.choice(len(d), quota, replace=False))]
        chunks.append(d)
        owners.append(np.full(len(d), i))
        if progress is not None:
            progress(name, i + 1, len(images))
    pool = np.concatenate(chunks)
    owner = np.concatenate(owners)
    if len(pool) < 2:
        raise ValueError(f"the images gave only {len(pool)} {kind} descriptors; need >= 2")
    if len(pool) > n_patches:
        pick = np.sort(rng.choice(len(pool), n_patches, replace=False))
        pool, owner = pool[pick], owner[pick]
    counts = {images[i][0]: int(c) for i, c in enumerate(np.bincount(owner, minlength=len(images)))}
    return pool, counts


def train_basis(
    kind: str,
    images: Sequence[tuple[str, np.ndarray]],
    *,
    n_patches: int = 20000,
    k: int | None = None,
    seed: int = 0,
    max_features: int = 3000,
    provenance: dict | None = None,
    progress: Progress | None = None,
) -> PcaBasis:
    """Fit the PCA basis of ``kind`` (equations 18-19) on descriptors sampled from ``images``.

    Parameters
    ----------
    kind : str
        One of :data:`vision.features.pca.BASIS_KINDS`.
    images : sequence of (name, rgb uint8 (H, W, 3))
        Training images; the names are recorded in the provenance.
    n_patches : int
        Descriptors (patches) to fit on; the chapter uses about 20,000.
    k : int, optional
        Components kept; default the kind's standard (36, 128, 128, 64).
    seed : int
        Seed of the sampling (the fit itself is deterministic).
    max_features : int
        Strongest keypoints per image.
    provenance : dict, optional
        Extra JSON-serialisable facts to record (e.g. where the images came from).
    progress : callable, optional
        ``progress(image_name, done, total)`` after each image.

    Returns
    -------
    PcaBasis
        With provenance: sources and their patch counts, total patches, date, seed, k, D,
        explained variance.
    """
    k = BASIS_KINDS[kind][1] if k is None and kind in BASIS_KINDS else k
    samples, counts = sample_training_set(
        kind,
        images,
        n_patches=n_patches,
        seed=seed,
        max_features=max_features,
        progress=progress,
    )
    record = {
        "kind": kind,
        "sources": [
            {"name": name, "shape": list(np.asarray(rgb).shape), "patches": counts[name]}
            for name, rgb in images
        ],
        "patches": len(samples),
        "patches_requested": int(n_patches),
        "max_features_per_image": int(max_features),
        "seed": int(seed),
        "date": _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds"),
        "opencv": cv2.__version__,
        **(provenance or {}),
    }
    if k is None:
        raise ValueError(f"k must be given for a basis of kind {kind!r} (no standard size)")
    basis = fit_pca(samples, int(k), kind=kind, provenance=record)
    prov = dict(basis.provenance, dim_in=basis.dim_in, k=basis.dim_out)
    prov["explained_variance"] = round(basis.explained_variance, 6)
    return PcaBasis(
        basis.mean, basis.components, basis.eigenvalues, kind, prov, basis.total_variance
    )
