"""External energy and forces for the active contour (chapter eqs. 10-11) and helpers.

Edge strength
    ``g = |grad G_sigma * I|`` (eq. 11): Gaussian smoothing (``cv2.GaussianBlur``) then
    Sobel derivatives.  For colour images the gradient magnitude is Di Zenzo's (1986): the
    square root of the largest eigenvalue of the summed channel structure tensor, so that an
    edge between two colours of equal brightness still counts.  ``g`` is divided by its 99th
    percentile ``g_ref`` (``g_hat = g / g_ref``) so that ``lam`` and ``eps`` below mean the same
    on every image whatever its contrast.

Eq. 11 edge energy (the default external term)
    ``E_img = 1 / (lam * (g_hat + eps))``.  The chapter's ``1 / (lam |grad G_sigma * I|)`` is
    infinite wherever the smoothed image is flat; the guard ``eps`` (default 0.1, i.e. a tenth
    of the image's strong-edge gradient) bounds it by ``1 / (lam eps)`` and also limits how
    much faint texture far from edges can pull.  The force is ``-grad E_img``.

Additions (documented departures; the eq. 11 term stays available and default)
    - ``balloon``: a pressure along the contour normal (Cohen 1991, "On active contour models
      and balloons"), scaled by the edge-stopping weight ``1 / (1 + (g_hat / stop_k)^2)`` of
      geodesic active contours (Caselles, Kimmel, Sapiro 1997) so it fades on edges.  It gives
      the snake a capture range: eq. 11's pull reaches only a few ``sigma`` from an edge.
    - ``"gvf"``: gradient vector flow (Xu and Prince 1998), the edge map's gradient diffused
      into flat regions, as an alternative force field with a long capture range.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import cv2
import numpy as np
from numpy.typing import NDArray

from vision.segmentation.validation import check_int, check_positive

__all__ = [
    "ExternalField",
    "edge_energy",
    "edge_strength",
    "external_field",
    "gradient_vector_flow",
    "sample_bilinear",
    "sample_remap",
]

ExternalMode = Literal["edge", "gvf"]


def edge_strength(
    image01: NDArray[np.float32], sigma_px: float
) -> tuple[NDArray[np.float32], float]:
    """Normalised edge strength ``g_hat = |grad G_sigma * I| / g_ref`` and ``g_ref``.

    Parameters
    ----------
    image01 : ndarray of shape (H, W) or (H, W, 3), float32 in [0, 1]
    sigma_px : float
        Standard deviation of ``G_sigma`` in pixels (eq. 11).

    Returns
    -------
    g_hat : ndarray of shape (H, W), float32
    g_ref : float
        The 99th percentile of ``|grad G_sigma * I|`` (per pixel, image units), at least 1e-6.
    """
    blur = cv2.GaussianBlur(image01, (0, 0), sigma_px, borderType=cv2.BORDER_REFLECT)
    # Sobel 3x3 is 8x the central difference of the smoothed image; scale back to per-pixel.
    gx = cv2.Sobel(blur, cv2.CV_32F, 1, 0, ksize=3, scale=0.125, borderType=cv2.BORDER_REFLECT)
    gy = cv2.Sobel(blur, cv2.CV_32F, 0, 1, ksize=3, scale=0.125, borderType=cv2.BORDER_REFLECT)
    if blur.ndim == 2:
        g = cv2.magnitude(gx, gy)
    else:
        # Di Zenzo: largest eigenvalue of sum_c [gx gy]^T [gx gy]; channel sums by cv2.transform.
        ones = np.ones((1, 3), np.float32)
        sxx = cv2.transform(gx * gx, ones)
        syy = cv2.transform(gy * gy, ones)
        sxy = cv2.transform(gx * gy, ones)
        half = 0.5 * (sxx - syy)
        g = cv2.sqrt(np.maximum(0.5 * (sxx + syy) + cv2.sqrt(half * half + sxy * sxy), 0.0))
    g_ref = max(float(np.percentile(g[::2, ::2], 99.0)), 1e-6)
    return (g * np.float32(1.0 / g_ref)).astype(np.float32), g_ref


def edge_energy(g_hat: NDArray[np.float32], *, lam: float, eps: float) -> NDArray[np.float32]:
    """Eq. 11 with its guard: ``E_img = 1 / (lam * (g_hat + eps))``, shape (H, W) float32."""
    return (np.float32(1.0 / lam) / (g_hat + np.float32(eps))).astype(np.float32)


def _central_gradient(field: NDArray[np.float32]) -> NDArray[np.float32]:
    """``(d/dx, d/dy)`` by central differences, stacked to (H, W, 2)."""
    dx = cv2.Sobel(field, cv2.CV_32F, 1, 0, ksize=1, scale=0.5, borderType=cv2.BORDER_REPLICATE)
    dy = cv2.Sobel(field, cv2.CV_32F, 0, 1, ksize=1, scale=0.5, borderType=cv2.BORDER_REPLICATE)
    return np.dstack([dx, dy])


def gradient_vector_flow(
    edge_map: NDArray[np.float32], *, mu: float = 0.2, iterations: int = 80
) -> NDArray[np.float32]:
    """Gradient vector flow of an edge map (Xu and Prince 1998, eq. 12 of their paper).

    Minimises ``mu |grad v|^2 + |grad f|^2 |v - grad f|^2`` by the explicit iteration
    ``v <- v + mu lap(v) - (v - grad f) |grad f|^2`` (unit time step; stable for mu <= 1/4).
    The edge map is scaled to [0, 1] first, as the paper prescribes.

    Returns
    -------
    ndarray of shape (H, W, 2), float32
        The flow ``(u, v)`` along x and y.
    """
    if not 0.0 < mu <= 0.25:
        raise ValueError(f"gvf_mu must be in (0, 0.25] for a stable iteration, got {mu!r}")
    check_int(iterations, "gvf_iterations", minimum=1)
    f = np.clip(edge_map, 0.0, 1.0).astype(np.float32)
    grad = _central_gradient(f)
    mag2 = (grad * grad).sum(axis=2)
    b = mag2[:, :, None]
    c = grad * b
    v = grad.copy()
    mu32 = np.float32(mu)
    for _ in range(iterations):
        lap = cv2.Laplacian(v, cv2.CV_32F, ksize=1, borderType=cv2.BORDER_REPLICATE)
        v += mu32 * lap - v * b + c
    return v


@dataclass(frozen=True)
class ExternalField:
    """Everything the snake samples from the image, precomputed once per image.

    Attributes
    ----------
    energy : ndarray of shape (H, W), float32
        ``E_img`` of eq. 11 (with the guard), the term summed in eq. 10.
    force : ndarray of shape (H, W, 2), float32
        The external force ``(f_x, f_y)`` per pixel: ``-grad E_img`` (``"edge"``) or the
        normalised gradient vector flow (``"gvf"``), times the weight.
    stop : ndarray of shape (H, W), float32
        Edge-stopping weight in (0, 1] that scales the balloon pressure.
    g_ref : float
        The gradient magnitude that ``g_hat = 1`` stands for.
    """

    energy: NDArray[np.float32]
    force: NDArray[np.float32]
    stop: NDArray[np.float32]
    g_ref: float


def external_field(
    image01: NDArray[np.float32],
    *,
    sigma_px: float = 2.0,
    lam: float = 1.0,
    eps: float = 0.1,
    mode: ExternalMode = "edge",
    weight: float = 1.0,
    stop_k: float = 0.3,
    gvf_mu: float = 0.2,
    gvf_iterations: int = 80,
) -> ExternalField:
    """Precompute the external energy (eq. 11), its force and the balloon's stopping weight.

    Parameters
    ----------
    image01 : ndarray of shape (H, W) or (H, W, 3), float32 in [0, 1]
    sigma_px : float
        ``sigma`` of ``G_sigma`` (eq. 11), pixels.
    lam : float
        ``lambda`` of eq. 11.
    eps : float
        Guard of eq. 11 against division by zero, in units of ``g_ref``.
    mode : {"edge", "gvf"}
        ``"edge"``: force ``-grad E_img`` (eq. 11); ``"gvf"``: gradient vector flow of the
        edge strength, scaled to unit length where it is not vanishing.
    weight : float
        Factor on the force.
    stop_k : float
        Edge strength (in units of ``g_ref``) at which the balloon pressure halves.
    """
    sigma_px = check_positive(sigma_px, "sigma_px")
    lam = check_positive(lam, "lam")
    eps = check_positive(eps, "eps")
    stop_k = check_positive(stop_k, "stop_k")
    if mode not in ("edge", "gvf"):
        raise ValueError(f"external must be 'edge' or 'gvf', got {mode!r}")
    g_hat, g_ref = edge_strength(image01, sigma_px)
    energy = edge_energy(g_hat, lam=lam, eps=eps)
    if mode == "edge":
        force = -_central_gradient(energy)
    else:
        flow = gradient_vector_flow(g_hat, mu=gvf_mu, iterations=gvf_iterations)
        norm = np.sqrt((flow * flow).sum(axis=2, keepdims=True))
        floor = np.float32(1e-3 * max(float(norm.max()), 1e-12))
        force = flow / np.maximum(norm, floor)
    if weight != 1.0:
        force *= np.float32(weight)
    stop = (1.0 / (1.0 + (g_hat * np.float32(1.0 / stop_k)) ** 2)).astype(np.float32)
    return ExternalField(
        energy=energy, force=np.ascontiguousarray(force, np.float32), stop=stop, g_ref=g_ref
    )


def sample_bilinear(field: NDArray[np.float32], xy: NDArray[np.float64]) -> NDArray[np.float64]:
    """Bilinear interpolation of ``field`` (H, W) or (H, W, C) at ``(x, y)`` points (N, 2).

    Points are clamped to the pixel centres' range ``[0, W-1] x [0, H-1]``.
    Returns (N,) or (N, C).
    """
    h, w = field.shape[:2]
    flat = field.reshape(h * w, -1)
    x = np.clip(xy[:, 0], 0.0, w - 1.0)
    y = np.clip(xy[:, 1], 0.0, h - 1.0)
    x0 = np.minimum(x.astype(np.intp), w - 2)
    y0 = np.minimum(y.astype(np.intp), h - 2)
    fx = (x - x0)[:, None]
    fy = (y - y0)[:, None]
    i = y0 * w + x0
    top = flat[i] * (1.0 - fx) + flat[i + 1] * fx
    bot = flat[i + w] * (1.0 - fx) + flat[i + w + 1] * fx
    out = top * (1.0 - fy) + bot * fy
    return out[:, 0] if field.ndim == 2 else out


def sample_remap(field: NDArray[np.float32], xy: NDArray[np.float64]) -> NDArray[np.float64]:
    """Bilinear samples of a float32 (H, W, C<=4) field at ``(x, y)`` points via ``cv2.remap``.

    The fast path of the snake's inner loop.  OpenCV quantises the interpolation weights to
    1/32 pixel (``INTER_TAB_SIZE``); positions themselves stay exact.  Out-of-range points
    take the nearest border value.  Returns (N, C) float64.
    """
    m = xy.astype(np.float32).reshape(-1, 1, 2)
    out = cv2.remap(field, m, None, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)  # type: ignore[call-overload]
    return np.asarray(out).reshape(xy.shape[0], -1).astype(np.float64)
