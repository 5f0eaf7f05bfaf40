"""Figures of the segmentation benchmark (matplotlib, Agg backend)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
from numpy.typing import NDArray

from benchmarks.segmentation_cases import Case, roi_box
from vision.segmentation import box_contour, chan_vese, contour_from_mask, region_contours

OURS, THEIRS, REF, INIT = "#ff3b30", "#e040fb", "#00e676", "#40c4ff"
LOCAL = "#ffb300"


def _closed(c: NDArray[np.float64]) -> NDArray[np.float64]:
    return np.vstack([c, c[:1]]) if len(c) else c


def _show(ax: Any, case: Case, box: tuple[int, int, int, int]) -> None:
    x0, y0, x1, y1 = box
    img = case.image[y0:y1, x0:x1]
    ax.imshow(
        img, cmap="gray" if img.ndim == 2 else None, extent=(x0 - 0.5, x1 - 0.5, y1 - 0.5, y0 - 0.5)
    )
    ax.set_xticks([])
    ax.set_yticks([])


def _save(fig: Any, out: Path, docs: Path | None, dpi: int) -> None:
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=dpi)
    if docs is not None:
        from PIL import Image

        docs.parent.mkdir(parents=True, exist_ok=True)
        # Palette PNG: the README copy stays well under 300 KB.
        Image.open(out).convert("RGB").quantize(colors=128, method=Image.Quantize.MEDIANCUT).save(
            docs, optimize=True
        )
    plt.close(fig)


def comparison_figure(
    rows: list[dict[str, Any]], out: Path, docs: Path | None = None, *, dpi: int = 90
) -> None:
    """Initial and final contours per image: snakes (top row) and level sets (bottom row)."""
    n = len(rows)
    fig, axes = plt.subplots(2, n, figsize=(3.1 * n, 8.2), squeeze=False)
    for j, r in enumerate(rows):
        case: Case = r["case"]
        box = roi_box(case.init, case.image.shape)
        ref = contour_from_mask(case.reference)
        for i in range(2):
            ax = axes[i, j]
            _show(ax, case, box)
            ax.plot(*_closed(ref).T, color=REF, lw=1.0, ls=":", label="reference")
            ax.plot(*_closed(case.init).T, color=INIT, lw=1.0, ls="--", label="initial")
        so, ss = r["snake_ours"], r["snake_skimage"]
        ax = axes[0, j]
        ax.plot(*_closed(ss.contour).T, color=THEIRS, lw=1.3, label="skimage active_contour")
        ax.plot(*_closed(so.contour).T, color=OURS, lw=1.3, label="ours")
        ax.set_title(f"{case.name}: {case.description}", fontsize=8)
        ax.set_xlabel(
            f"ours IoU {so.iou:.3f}, {1e3 * so.seconds:.1f} ms\n"
            f"skimage IoU {ss.iou:.3f}, {1e3 * ss.seconds:.0f} ms",
            fontsize=8,
        )
        lo, lm, ll = r["levelset_ours"], r["levelset_mcv"], r.get("levelset_local")
        ax = axes[1, j]
        for c in region_contours(lm.mask):
            ax.plot(*_closed(c).T, color=THEIRS, lw=1.2)
        for c in region_contours(lo.mask):
            ax.plot(*_closed(c).T, color=OURS, lw=1.2)
        label = (
            f"ours IoU {lo.iou:.3f}, {1e3 * lo.seconds:.0f} ms\n"
            f"MCV IoU {lm.iou:.3f}, {1e3 * lm.seconds:.0f} ms"
        )
        if ll is not None:
            for c in region_contours(ll.mask):
                ax.plot(*_closed(c).T, color=LOCAL, lw=1.2)
            label += f"\nlocalised IoU {ll.iou:.3f}, {1e3 * ll.seconds:.0f} ms"
        ax.set_xlabel(label, fontsize=8)
    axes[0, 0].set_ylabel("snake (active_contour)", fontsize=9)
    axes[1, 0].set_ylabel("level set (Chan-Vese / MCV)", fontsize=9)
    handles, labels = axes[0, 0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="lower center", ncol=4, fontsize=8, frameon=False)
    fig.suptitle(
        "Initial (dashed) and final contours: ours (red; level set: global red, localised "
        "orange) vs scikit-image (magenta); IoU against the reference (dotted) and wall time",
        fontsize=9,
    )
    fig.tight_layout(rect=(0, 0.04, 1, 0.95), h_pad=1.5)
    _save(fig, out, docs, dpi=dpi)


def evolution_figure(
    cases: list[Case],
    out: Path,
    docs: Path | None = None,
    *,
    name: str = "coins",
    method: str = "pde",
) -> None:
    """The chapter's Figure 3 style: the level-set contour at iterations 0, 20, 50 and 70.

    Chan-Vese, on colour when the image has it (its PDE solver by default: the front moves at most a pixel per
    iteration, so the evolution is gradual), started from a box just inside the crop around
    the object, with the solver's default parameters.
    """
    case = next(c for c in cases if c.name == name)
    x0, y0, x1, y1 = roi_box(case.init, case.image.shape)
    crop = np.ascontiguousarray(case.image[y0:y1, x0:x1])
    h, w = crop.shape[:2]
    init = box_contour(4, 4, w - 5, h - 5, n_points=400)
    shots = (0, 20, 50, 70)
    res = chan_vese(crop, init, method=method, snapshot_at=shots, max_num_iter=600)
    fig, axes = plt.subplots(1, 5, figsize=(14, 2.9))
    panels = [*res.snapshots, (res.iterations, region_contours(res.mask))]
    state = "converged" if res.converged else "stopped"
    titles = [
        "(a) initial",
        "(b) 20 iterations",
        "(c) 50 iterations",
        "(d) 70 iterations",
        f"(e) {state} after {res.iterations} iterations",
    ]
    for ax, (_, contours), title in zip(axes, panels, titles, strict=False):
        ax.imshow(crop, cmap="gray" if crop.ndim == 2 else None)
        for c in contours:
            ax.plot(*_closed(c).T, color="#ffeb3b", lw=1.2)
        ax.set_title(title, fontsize=9)
        ax.set_xticks([])
        ax.set_yticks([])
    fig.suptitle(
        f"Level-set contour evolution (Chan-Vese, {method} solver, {case.name})", fontsize=10
    )
    fig.tight_layout()
    _save(fig, out, docs, dpi=80)
