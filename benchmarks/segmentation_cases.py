"""Benchmark images for segmentation: objects, reference masks and initial contours.

Every case is an image, one object in it, a reference mask for that object made by a
documented and reproducible procedure, and an initial contour (a loose ellipse around the
object) that every method starts from.

Providers
---------
A provider is a function ``() -> list[Case]``; :data:`PROVIDERS` maps names to them and the
benchmark runs the ones asked for (all by default).  ``skimage`` serves the four photographs
scikit-image ships inside its wheel (``skimage.data``: no download).  ``sim`` renders five
wheel types on the belt with the simulated cell's eye-in-hand camera and takes each reference
mask from MuJoCo's segmentation render (:mod:`benchmarks.segmentation_sim`, where its
procedure is written down).  A provider that cannot run here (no MuJoCo rendering) raises
:class:`ProviderUnavailable` and the benchmark skips it with the reason.

Reference procedure (``skimage`` provider)
------------------------------------------
1. A hand-drawn polygon around the object (the vertices below, pixel coordinates).
2. GrabCut (Rother, Kolmogorov and Blake 2004; ``cv2.grabCut``, 8 iterations, OpenCV's RNG
   seeded with 0) initialised from the polygon: definite foreground = the polygon eroded by
   12 px, probable foreground = the polygon, probable background = a 12 px band outside it,
   definite background = the rest.
3. The largest 4-connected foreground component, with its holes filled.

The objects: one coin (``coins``, the large coin top right), the cup's mouth (``coffee``: the
white rim and the coffee inside it, bounded by the rim's outer edge), the astronaut's head
(``astronaut``: hair, face and neck down to the suit's collar), and the cat's left eye
(``chelsea``: iris, pupil and dark rim).  The cat's whole head fills the ``chelsea`` frame,
so its eye is the object there.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import NDArray

from vision.segmentation import ellipse_contour

__all__ = [
    "PROVIDERS",
    "Case",
    "ProviderUnavailable",
    "all_cases",
    "reference_mask",
    "roi_box",
    "skimage_cases",
]


class ProviderUnavailable(RuntimeError):
    """A provider cannot produce its images here (the reason is the message)."""


@dataclass(frozen=True)
class Case:
    """One benchmark image with its object.

    Attributes
    ----------
    name : str
        Short name (the table row).
    provider : str
        Where the image comes from.
    description : str
        The object, in words.
    image : ndarray of shape (H, W) or (H, W, 3), uint8
        Grey or RGB.
    reference : ndarray of shape (H, W), bool
        The object's reference mask.
    init : ndarray of shape (N, 2)
        The initial contour, ``(x, y)`` pixels, shared by every method.
    """

    name: str
    provider: str
    description: str
    image: NDArray[np.uint8]
    reference: NDArray[np.bool_]
    init: NDArray[np.float64]


def reference_mask(
    image: NDArray[np.uint8],
    polygon: list[tuple[int, int]],
    *,
    band_px: int = 12,
    iterations: int = 8,
    seed: int = 0,
) -> NDArray[np.bool_]:
    """Reference mask of the object inside ``polygon`` (steps 2-3 of the module docstring)."""
    rgb = image if image.ndim == 3 else np.dstack([image] * 3)
    h, w = rgb.shape[:2]
    poly = np.asarray(polygon, dtype=np.int32).reshape(-1, 1, 2)
    inside = np.zeros((h, w), np.uint8)
    cv2.fillPoly(inside, [poly], 1)
    k = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * band_px + 1, 2 * band_px + 1))
    trimap = np.full((h, w), cv2.GC_BGD, np.uint8)
    trimap[cv2.dilate(inside, k) > 0] = cv2.GC_PR_BGD
    trimap[inside > 0] = cv2.GC_PR_FGD
    trimap[cv2.erode(inside, k) > 0] = cv2.GC_FGD
    cv2.setRNGSeed(seed)
    bgd, fgd = np.zeros((1, 65)), np.zeros((1, 65))
    cv2.grabCut(
        cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR),
        trimap,
        None,
        bgd,
        fgd,
        iterations,
        cv2.GC_INIT_WITH_MASK,
    )
    fg = ((trimap == cv2.GC_FGD) | (trimap == cv2.GC_PR_FGD)).astype(np.uint8)
    n, labels, stats, _ = cv2.connectedComponentsWithStats(fg, connectivity=4)
    if n > 1:
        fg = (labels == 1 + int(np.argmax(stats[1:, cv2.CC_STAT_AREA]))).astype(np.uint8)
    # Fill holes: background components that do not touch the border.
    n, labels = cv2.connectedComponents(1 - fg, connectivity=4)
    border = np.unique(np.concatenate([labels[0], labels[-1], labels[:, 0], labels[:, -1]]))
    holes = (fg == 0) & ~np.isin(labels, border)
    return (fg > 0) | holes


# (loader name, polygon (x, y), init ellipse centre, semi-axes, description)
_SKIMAGE_OBJECTS: dict[
    str, tuple[list[tuple[int, int]], tuple[float, float], tuple[float, float], str]
] = {
    "coins": (
        [
            (335, 15),
            (350, 19),
            (360, 29),
            (364, 44),
            (360, 59),
            (350, 69),
            (335, 73),
            (320, 69),
            (310, 59),
            (306, 44),
            (310, 29),
            (320, 19),
        ],
        (335.0, 44.0),
        (40.0, 40.0),
        "the large coin at the top right",
    ),
    "coffee": (
        [
            (408, 112),
            (392, 159),
            (349, 193),
            (291, 206),
            (232, 193),
            (190, 159),
            (174, 112),
            (190, 65),
            (232, 31),
            (291, 18),
            (349, 31),
            (392, 65),
        ],
        (291.0, 112.0),
        (132.0, 106.0),
        "the cup's mouth: white rim and coffee",
    ),
    "astronaut": (
        [
            (225, 15),
            (260, 20),
            (285, 40),
            (300, 70),
            (302, 100),
            (292, 120),
            (278, 125),
            (270, 150),
            (262, 172),
            (215, 178),
            (195, 160),
            (185, 140),
            (180, 125),
            (160, 115),
            (150, 95),
            (155, 60),
            (175, 35),
            (200, 20),
        ],
        (226.0, 100.0),
        (95.0, 92.0),
        "the head: hair, face, neck to the collar",
    ),
    "chelsea": (
        [
            (150, 86),
            (175, 82),
            (195, 90),
            (207, 105),
            (207, 125),
            (198, 140),
            (178, 146),
            (155, 142),
            (140, 130),
            (135, 112),
            (140, 96),
        ],
        (171.0, 114.0),
        (50.0, 42.0),
        "the cat's left eye",
    ),
}


def skimage_cases(n_points: int = 200) -> list[Case]:
    """The four scikit-image photographs (bundled in the wheel, no network)."""
    import skimage.data

    cases = []
    for name, (polygon, center, axes, text) in _SKIMAGE_OBJECTS.items():
        image = np.ascontiguousarray(getattr(skimage.data, name)())
        cases.append(
            Case(
                name=name,
                provider="skimage",
                description=text,
                image=image,
                reference=reference_mask(image, polygon),
                init=ellipse_contour(center, axes, n_points=n_points),
            )
        )
    return cases


def sim_cases(n_points: int = 200) -> list[Case]:
    """Wheels rendered by the simulated cell (:func:`benchmarks.segmentation_sim.sim_cases`)."""
    from benchmarks.segmentation_sim import sim_cases as render_wheels

    return render_wheels(n_points)


#: Image providers of the benchmark, in order.
PROVIDERS: dict[str, Callable[[], list[Case]]] = {"skimage": skimage_cases, "sim": sim_cases}


def all_cases(
    providers: Sequence[str] | None = None,
) -> tuple[list[Case], dict[str, str]]:
    """The cases of ``providers`` (default: all), in provider order, and the providers
    skipped because they cannot run here, with the reason.

    Raises ``ValueError`` for an unknown provider name.
    """
    names = list(PROVIDERS) if providers is None else list(providers)
    unknown = [n for n in names if n not in PROVIDERS]
    if unknown:
        raise ValueError(f"unknown provider(s) {unknown}; valid: {', '.join(PROVIDERS)}")
    cases: list[Case] = []
    skipped: dict[str, str] = {}
    for name in names:
        try:
            cases.extend(PROVIDERS[name]())
        except ProviderUnavailable as exc:
            skipped[name] = str(exc)
    return cases, skipped


def roi_box(
    init: NDArray[np.float64], shape: tuple[int, ...], margin_px: int = 16
) -> tuple[int, int, int, int]:
    """``(x0, y0, x1, y1)``: the initial contour's bounding box grown by ``margin_px``, clipped."""
    h, w = shape[:2]
    x0, y0 = np.floor(init.min(axis=0) - margin_px).astype(int)
    x1, y1 = np.ceil(init.max(axis=0) + margin_px).astype(int) + 1
    return max(int(x0), 0), max(int(y0), 0), min(int(x1), w), min(int(y1), h)
