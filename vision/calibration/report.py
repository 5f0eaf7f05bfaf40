"""Report pictures of calibrations (PNG bytes, matplotlib with the Agg backend).

- :func:`residuals_png`: reprojection error per image (intrinsics) or per robot pose
  (hand-eye: millimetres, degrees and pixels).
- :func:`coverage_png`: where in the image corners were seen.
- :func:`consistency_png`: the board's position in the base frame as predicted from every
  hand-eye sample, around the solution.
- :func:`summary_png`: the four together, for the README.
"""

from __future__ import annotations

import io
from typing import Any

import numpy as np

from vision.calibration.coverage import CoverageMap
from vision.calibration.handeye import HandEyeResult
from vision.calibration.intrinsics import IntrinsicsResult

__all__ = ["consistency_png", "coverage_png", "residuals_png", "summary_png"]

_OK = "#2f6db5"
_BAD = "#c0392b"
_GREY = "#9ca3af"


def _figure(w_in: float, h_in: float, *, nrows: int = 1, ncols: int = 1, **kw: Any) -> Any:
    from matplotlib.figure import Figure

    fig = Figure(figsize=(w_in, h_in), dpi=100, layout="constrained")
    axes = fig.subplots(nrows, ncols, **kw)
    return fig, axes


def _png(fig: Any, dpi: int = 100) -> bytes:
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    FigureCanvasAgg(fig)
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi)
    return buf.getvalue()


def _short(name: str) -> str:
    stem = name.rsplit("/", 1)[-1]
    return stem.rsplit(".", 1)[0] if "." in stem else stem


def _intrinsic_bars(ax: Any, r: IntrinsicsResult) -> None:
    entries = sorted(
        [(v.index, _short(v.name), v.rms_px, v.max_px, True) for v in r.views]
        + [(x.index, _short(x.name), 0.0, 0.0, False) for x in r.rejected]
    )
    xs = np.arange(len(entries))
    rms = [e[2] for e in entries]
    colors = [_OK if e[4] else _BAD for e in entries]
    ax.bar(xs, rms, color=colors, label="RMS per image")
    ax.plot(
        [x for x, e in zip(xs, entries, strict=True) if e[4]],
        [e[3] for e in entries if e[4]],
        "k_",
        markersize=9,
        label="largest corner error",
    )
    for x, e in zip(xs, entries, strict=True):
        if not e[4]:
            ax.text(
                x, 0.0, "rejected", rotation=90, ha="center", va="bottom", color=_BAD, fontsize=7
            )
    ax.axhline(r.rms_px, color="k", lw=0.8, ls="--", label=f"overall RMS {r.rms_px:.3f} px")
    ax.set_xticks(xs, [e[1] for e in entries], rotation=60, ha="right", fontsize=7)
    ax.set_ylabel("reprojection error (px)")
    ax.set_title(f"Intrinsics: {len(r.views)} images used, {len(r.rejected)} rejected", fontsize=10)
    ax.legend(fontsize=7, loc="upper left")


def _hand_eye_bars(ax: Any, r: HandEyeResult) -> None:
    names = [_short(p.name) for p in r.poses]
    xs = np.arange(len(names))
    mm = [p.translation_mm for p in r.poses]
    deg = [p.rotation_deg for p in r.poses]
    ax.bar(xs - 0.2, mm, width=0.4, color=_OK, label="board position (mm)")
    ax2 = ax.twinx()
    ax2.bar(xs + 0.2, deg, width=0.4, color="#e07a1e", label="board orientation (deg)")
    ax.set_ylabel("mm", color=_OK)
    ax2.set_ylabel("deg", color="#e07a1e")
    mm_rms, deg_rms = r.consistency_mm[0], r.consistency_deg[0]
    ax.set_title(
        f"Hand-eye per pose ({r.method}{' + refined' if r.refined else ''}): "
        f"RMS {mm_rms:.2f} mm / {deg_rms:.3f} deg, reprojection {r.rms_px:.2f} px",
        fontsize=10,
    )
    ax.set_xticks(xs, names, rotation=60, ha="right", fontsize=7)
    h1, l1 = ax.get_legend_handles_labels()
    h2, l2 = ax2.get_legend_handles_labels()
    ax.legend(h1 + h2, l1 + l2, fontsize=7, loc="upper left")


def _coverage(ax: Any, cov: CoverageMap, title: str) -> Any:
    w, h = cov.image_size
    counts = cov.counts
    im = ax.imshow(
        counts, extent=(-0.5, w - 0.5, h - 0.5, -0.5), cmap="viridis", interpolation="nearest"
    )
    gr, gc = counts.shape
    for r in range(gr):
        for c in range(gc):
            ax.text(
                (c + 0.5) * w / gc - 0.5,
                (r + 0.5) * h / gr - 0.5,
                str(int(counts[r, c])),
                ha="center",
                va="center",
                fontsize=7,
                color="w" if counts[r, c] < counts.max() * 0.6 else "k",
            )
    ax.set_xlim(-0.5, w - 0.5)
    ax.set_ylim(h - 0.5, -0.5)
    ax.set_aspect("equal")
    ax.set_xlabel("u (px)")
    ax.set_ylabel("v (px)")
    ax.set_title(
        f"{title}: corners per cell, {cov.fraction:.0%} of cells, {cov.corner_cells}/4 image corners",
        fontsize=10,
    )
    return im


def _consistency(ax: Any, r: HandEyeResult) -> None:
    off = np.array([p.offset_mm for p in r.poses])
    ax.scatter(off[:, 0], off[:, 1], c=_OK, s=18, label="x-y")
    ax.scatter(off[:, 0], off[:, 2], c="#e07a1e", s=18, marker="^", label="x-z")
    lim = max(1.0, float(np.abs(off).max()) * 1.2)
    ax.set_xlim(-lim, lim)
    ax.set_ylim(-lim, lim)
    ax.set_aspect("equal")
    ax.axhline(0, color=_GREY, lw=0.6)
    ax.axvline(0, color=_GREY, lw=0.6)
    ax.set_xlabel("x offset (mm, base frame)")
    ax.set_ylabel("y or z offset (mm)")
    mm_rms, mm_max = r.consistency_mm
    ax.set_title(
        f"Board origin in base, per pose:\nRMS {mm_rms:.2f} mm, max {mm_max:.2f} mm", fontsize=10
    )
    ax.legend(fontsize=7)


def residuals_png(result: IntrinsicsResult | HandEyeResult) -> bytes:
    """Bar chart of the residuals per image (intrinsics) or per robot pose (hand-eye)."""
    if isinstance(result, IntrinsicsResult):
        fig, ax = _figure(8.0, 3.6)
        _intrinsic_bars(ax, result)
    elif isinstance(result, HandEyeResult):
        fig, ax = _figure(8.0, 3.6)
        _hand_eye_bars(ax, result)
    else:
        raise ValueError(
            f"result must be an IntrinsicsResult or a HandEyeResult, got {type(result)}"
        )
    return _png(fig)


def coverage_png(coverage: CoverageMap, *, title: str = "Coverage") -> bytes:
    """Heat map of the corners seen per cell of the image."""
    w, h = coverage.image_size
    fig, ax = _figure(6.4, 6.4 * h / w + 0.8)
    im = _coverage(ax, coverage, title)
    fig.colorbar(im, ax=ax, shrink=0.8)
    return _png(fig)


def consistency_png(result: HandEyeResult) -> bytes:
    """Scatter of the board origin predicted from each hand-eye sample around the solution."""
    fig, ax = _figure(5.2, 5.2)
    _consistency(ax, result)
    return _png(fig)


def summary_png(
    intrinsics: IntrinsicsResult, hand_eye: HandEyeResult | None = None, *, dpi: int = 72
) -> bytes:
    """One picture with the per-image residuals and coverage of ``intrinsics`` and, if given,
    the per-pose residuals and board consistency of ``hand_eye``."""
    rows = 2 if hand_eye is not None else 1
    fig, axes = _figure(13.0, 4.6 * rows, nrows=rows, ncols=2, squeeze=False)
    _intrinsic_bars(axes[0][0], intrinsics)
    _coverage(axes[0][1], intrinsics.coverage, "Coverage")
    if hand_eye is not None:
        _hand_eye_bars(axes[1][0], hand_eye)
        _consistency(axes[1][1], hand_eye)
    return _png(fig, dpi=dpi)
