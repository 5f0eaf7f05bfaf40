"""PCA dimension reduction of descriptors (chapter section 3.4.2, equations 18-19).

A :class:`PcaBasis` holds the sample mean and the leading eigenvectors of the descriptors'
covariance matrix; :meth:`PcaBasis.project` computes ``Y = U (X - mean)`` (equation 18 with
the mean shift the chapter describes before equation 19). Bases are trained by
``visioncell train-pca`` (:mod:`vision.features.pca_training`) and shipped as versioned
``.npz`` files in ``vision/features/data/<kind>.npz``.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path

import numpy as np

from vision.features.types import _frozen

__all__ = [
    "BASIS_KINDS",
    "DATA_DIR",
    "PcaBasis",
    "default_basis",
    "fit_pca",
    "load_npz",
    "save_npz",
]

#: Directory of the shipped bases (package data).
DATA_DIR = Path(__file__).resolve().parent / "data"
#: Descriptor kinds with a shipped basis: raw dimension D and reduced dimension k.
BASIS_KINDS: dict[str, tuple[int, int]] = {
    "pca-sift": (3042, 36),
    "gloh": (272, 128),
    "color-sift": (256, 32),  # the joint layout's two colour blocks; the grey block stays whole
    "color-surf": (128, 16),
    "color-sift-chapter": (384, 128),
    "color-surf-chapter": (192, 64),
}
_FORMAT = 1


@dataclass(frozen=True, eq=False)
class PcaBasis:
    """A trained PCA projection ``Y = U (X - mean)`` (chapter equation 18).

    Attributes
    ----------
    mean : ndarray of shape (D,), float32
        Sample mean of the training descriptors (``X-bar`` under equation 19).
    components : ndarray of shape (D, k), float32
        The k leading eigenvectors of the covariance (equation 19) as columns, in
        decreasing eigenvalue order; ``U`` of equation 18 is its transpose.
    eigenvalues : ndarray of shape (k,), float64
        Their eigenvalues (variance along each component).
    kind : str
        Descriptor the basis reduces (``"pca-sift"``, ``"gloh"``, ``"color-sift"``, ...).
    provenance : dict
        JSON-serialisable record of the training: sources, patch counts, date, seed, ...
    total_variance : float
        Trace of the full covariance (so ``explained_variance`` can be reported).
    version : str
        ``"<kind>-k<k>-<hash>"``: the hash covers the stored mean and components, so any new
        basis gives a new version (and :class:`~vision.features.Features` of different bases
        are never compared by mistake).
    """

    mean: np.ndarray
    components: np.ndarray
    eigenvalues: np.ndarray
    kind: str
    provenance: dict = field(default_factory=dict)
    total_variance: float = 0.0
    version: str = ""

    def __post_init__(self) -> None:
        mean = np.ascontiguousarray(self.mean, dtype=np.float32).reshape(-1)
        comp = np.ascontiguousarray(self.components, dtype=np.float32)
        ev = np.ascontiguousarray(self.eigenvalues, dtype=np.float64).reshape(-1)
        if comp.ndim != 2 or comp.shape[0] != mean.shape[0]:
            raise ValueError(f"components must have shape ({mean.shape[0]}, k), got {comp.shape}")
        if ev.shape[0] != comp.shape[1]:
            raise ValueError(f"eigenvalues has {ev.shape[0]} entries, components {comp.shape[1]}")
        if not self.kind:
            raise ValueError(f"kind must be a non-empty string, got {self.kind!r}")
        object.__setattr__(self, "mean", _frozen(mean))
        object.__setattr__(self, "components", _frozen(comp))
        object.__setattr__(self, "eigenvalues", _frozen(ev))
        object.__setattr__(self, "provenance", dict(self.provenance))
        digest = hashlib.sha256(mean.tobytes() + comp.tobytes()).hexdigest()[:12]
        object.__setattr__(self, "version", f"{self.kind}-k{comp.shape[1]}-{digest}")

    @property
    def dim_in(self) -> int:
        """Raw descriptor dimension D."""
        return int(self.mean.shape[0])

    @property
    def dim_out(self) -> int:
        """Reduced dimension k."""
        return int(self.components.shape[1])

    @property
    def explained_variance(self) -> float:
        """Fraction of the training variance the k components keep."""
        if self.total_variance <= 0:
            return float("nan")
        return float(self.eigenvalues.sum() / self.total_variance)

    def project(self, x: np.ndarray) -> np.ndarray:
        """Reduce descriptors: ``Y = U (X - mean)`` (equation 18), row-wise.

        Parameters
        ----------
        x : ndarray of shape (N, D) or (D,)

        Returns
        -------
        ndarray of shape (N, k) or (k,), float32
        """
        x = np.asarray(x, dtype=np.float32)
        if x.shape[-1] != self.dim_in:
            raise ValueError(
                f"descriptors have dimension {x.shape[-1]}, basis {self.kind!r} expects "
                f"{self.dim_in}"
            )
        return (x - self.mean) @ self.components


def fit_pca(
    samples: np.ndarray, k: int, *, kind: str = "custom", provenance: dict | None = None
) -> PcaBasis:
    """Fit a PCA basis to descriptors (chapter equations 18-19).

    The samples are mean-shifted, their covariance ``cov(X) = 1/(n-1) sum (X_i - X-bar)
    (X_i - X-bar)^T`` (equation 19) is eigen-decomposed (symmetric ``eigh``) and the k
    eigenvectors of largest eigenvalue become ``U`` (equation 18). Each eigenvector's sign is
    fixed so its largest-magnitude entry is positive, making the basis reproducible.

    Parameters
    ----------
    samples : ndarray of shape (n, D)
        Training descriptors, n >= 2.
    k : int
        Number of components, 1 <= k <= D.
    kind : str
        Descriptor kind recorded in the basis (and its version).
    provenance : dict, optional
        Training record stored with the basis.

    Returns
    -------
    PcaBasis
    """
    x = np.asarray(samples)
    if x.ndim != 2 or x.shape[0] < 2:
        raise ValueError(f"samples must have shape (n >= 2, D), got {x.shape}")
    if not np.all(np.isfinite(x)):
        raise ValueError("samples contain NaN or infinite values")
    n, d = x.shape
    if not isinstance(k, int | np.integer) or not 1 <= k <= d:
        raise ValueError(f"k must be an integer in [1, {d}], got {k!r}")
    mean = x.mean(axis=0, dtype=np.float64)
    cov = np.zeros((d, d))
    for c0 in range(0, n, 2048):  # float64 in chunks: 20,000 x 3042 would need 0.5 GB
        xc = x[c0 : c0 + 2048].astype(np.float64) - mean
        cov += xc.T @ xc
    cov /= n - 1  # equation 19
    evals, evecs = np.linalg.eigh(cov)
    order = np.argsort(evals)[::-1][:k]
    evals = np.clip(evals[order], 0.0, None)
    evecs = evecs[:, order]
    flip = np.sign(evecs[np.argmax(np.abs(evecs), axis=0), np.arange(k)])
    evecs = evecs * np.where(flip == 0, 1.0, flip)
    return PcaBasis(mean, evecs, evals, kind, dict(provenance or {}), float(np.trace(cov)))


def save_npz(basis: PcaBasis, path: str | Path, *, float16: bool = True) -> Path:
    """Write a basis as a compressed ``.npz`` (no pickles; provenance as JSON text).

    Parameters
    ----------
    basis : PcaBasis
    path : str or Path
    float16 : bool
        Store the components as float16 (half the size; the projection changes by about
        1e-3 relative, which leaves nearest-neighbour matching unchanged, see
        ``docs/readme/features-descriptors.md``). The version is that of the stored values,
        so a reloaded basis has a stable version.

    Returns
    -------
    Path
        The file written.
    """
    path = Path(path)
    comp = basis.components.astype(np.float16 if float16 else np.float32)
    stored = PcaBasis(
        basis.mean,
        comp.astype(np.float32),
        basis.eigenvalues,
        basis.kind,
        basis.provenance,
        basis.total_variance,
    )
    path.parent.mkdir(parents=True, exist_ok=True)
    np.savez_compressed(
        path,
        format=np.array(_FORMAT, dtype=np.int64),
        kind=np.array(basis.kind),
        version=np.array(stored.version),
        mean=basis.mean.astype(np.float32),
        components=comp,
        eigenvalues=basis.eigenvalues,
        total_variance=np.array(basis.total_variance, dtype=np.float64),
        provenance=np.array(json.dumps(basis.provenance, sort_keys=True)),
    )
    return path


def load_npz(path: str | Path) -> PcaBasis:
    """Read a basis written by :func:`save_npz` (``allow_pickle=False``).

    Raises
    ------
    ValueError
        The file is missing, not a basis, of an unknown format, or its stored version does
        not match its contents.
    """
    path = Path(path)
    if not path.is_file():
        raise ValueError(f"PCA basis file {str(path)!r} does not exist")
    try:
        with np.load(path, allow_pickle=False) as z:
            fmt = int(z["format"])
            if fmt != _FORMAT:
                raise ValueError(f"unsupported PCA basis format {fmt} (this code reads {_FORMAT})")
            basis = PcaBasis(
                z["mean"],
                z["components"].astype(np.float32),
                z["eigenvalues"],
                str(z["kind"]),
                json.loads(str(z["provenance"])),
                float(z["total_variance"]),
            )
            stored_version = str(z["version"])
    except (OSError, KeyError, ValueError) as exc:  # JSONDecodeError is a ValueError
        raise ValueError(f"{str(path)!r} is not a PCA basis file: {exc}") from exc
    if basis.version != stored_version:
        raise ValueError(
            f"{str(path)!r}: stored version {stored_version!r} does not match its contents "
            f"({basis.version!r}); the file is corrupt"
        )
    return basis


@lru_cache(maxsize=8)
def _load_default(path: str) -> PcaBasis:
    return load_npz(path)


def default_basis(kind: str) -> PcaBasis:
    """The shipped basis of a descriptor kind (``vision/features/data/<kind>.npz``).

    Parameters
    ----------
    kind : str
        One of :data:`BASIS_KINDS`.

    Raises
    ------
    ValueError
        Unknown kind, or the file is missing (train it with ``visioncell train-pca``).
    """
    if kind not in BASIS_KINDS:
        raise ValueError(f"unknown PCA basis kind {kind!r}; choose one of {', '.join(BASIS_KINDS)}")
    path = DATA_DIR / f"{kind}.npz"
    if not path.is_file():
        raise ValueError(
            f"no shipped PCA basis for {kind!r} at {str(path)!r}; run `visioncell train-pca`"
        )
    return _load_default(str(path))
