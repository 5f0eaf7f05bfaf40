"""Plots of the registration benchmark, in the style of chapter Figures 12, 14 and 16 (PNG,
matplotlib Agg). Each function takes the benchmark's plain records and returns the path."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt

_STYLE = {"dpi": 90}


def _curve(ax: Any, rec: dict[str, Any], label: str, **kw: Any) -> None:
    ax.plot(rec["curve_1mp"], rec["curve_recall"], label=label, **kw)


def _finish(ax: Any, title: str) -> None:
    ax.set_xlim(0, 1)
    ax.set_ylim(0, 1)
    ax.set_xlabel("1 - precision")
    ax.set_ylabel("recall")
    ax.set_title(title, fontsize=9)
    ax.grid(alpha=0.3)


def _save(fig: Any, path: Path) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.tight_layout()
    fig.savefig(path, **_STYLE)
    plt.close(fig)
    return path


def _by(records: list[dict[str, Any]], **match: Any) -> list[dict[str, Any]]:
    return [r for r in records if all(r.get(k) == v for k, v in match.items())]


def figure_scale(records: list[dict[str, Any]], methods: list[str], path: Path) -> Path | None:
    """Figure 12: (a) recall vs 1-precision at scale factor 2; (b) best recall vs scale."""
    if not _by(records, sequence="scale"):
        return None
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(9, 3.8))
    for m in methods:
        rs = sorted(_by(records, method=m, sequence="scale"), key=lambda r: r["param"])
        if not rs:
            continue
        two = [r for r in rs if abs(r["param"] - 2.0) < 1e-9]
        if two:
            _curve(ax1, two[0], m)
        ax2.plot([r["param"] for r in rs], [r["best_recall"] for r in rs], "o-", label=m)
    _finish(ax1, "(a) scale change of 2")
    if ax1.lines:
        ax1.legend(fontsize=7)
    ax2.set_xlabel("scale factor s (eq. 14)")
    ax2.set_ylabel("best recall")
    ax2.set_ylim(0, 1)
    ax2.grid(alpha=0.3)
    ax2.set_title("(b) recall for different scales", fontsize=9)
    return _save(fig, path)


def figure_viewpoint(records: list[dict[str, Any]], methods: list[str], path: Path) -> Path | None:
    """Figure 14: best recall and recall at 1-precision 0.1 vs graf viewpoint angle."""
    if not _by(records, sequence="graf"):
        return None
    fig, ax = plt.subplots(figsize=(5.5, 3.8))
    for m in methods:
        rs = sorted(_by(records, method=m, sequence="graf"), key=lambda r: r["param"])
        if not rs:
            continue
        x = [r["param"] for r in rs]
        line = ax.plot(x, [r["best_recall"] for r in rs], "o-", label=f"{m} best")[0]
        ax.plot(x, [r["recall_at_01"] for r in rs], "x--", color=line.get_color(), alpha=0.6)
    ax.set_xlabel("viewpoint angle (deg), graf img1 vs img2..6")
    ax.set_ylabel("recall (solid: best; dashed: at 1-p = 0.1)")
    ax.set_ylim(0, 1)
    ax.grid(alpha=0.3)
    if ax.lines:
        ax.legend(fontsize=7)
    return _save(fig, path)


def figure_colour(
    records: list[dict[str, Any]], pairs: list[tuple[str, str]], path: Path
) -> Path | None:
    """Figure 16: recall vs 1-precision of each colour descriptor and its grey base, on the
    illumination pairs (first photo) and the simulated wheel pairs: solid colour, dashed grey
    base, one colour per pair of methods."""
    sequences = [("illumination", None), ("sim-wheel", None)]
    panels = []
    for seq, _ in sequences:
        names = sorted({r["pair"] for r in records if r["sequence"] == seq})
        if seq == "illumination":
            first = names[0].split("/")[0] if names else ""
            names = [n for n in names if n.startswith(first + "/")]
        panels += [(seq, n) for n in names]
    if not panels or not pairs:
        return None
    cols = min(4, len(panels))
    rows = (len(panels) + cols - 1) // cols
    fig, axes = plt.subplots(rows, cols, figsize=(3.0 * cols, 2.9 * rows), squeeze=False)
    for ax, (seq, name) in zip(axes.flat, panels, strict=False):
        for k, (colour, grey) in enumerate(pairs):
            for m, style in ((colour, "-"), (grey, "--")):
                rs = _by(records, method=m, sequence=seq, pair=name)
                if rs:
                    _curve(ax, rs[0], m, linestyle=style, color=f"C{k}")
        _finish(ax, f"{seq} {name}")
    for ax in list(axes.flat)[len(panels) :]:
        ax.axis("off")
    axes.flat[0].legend(fontsize=7)
    return _save(fig, path)


def figure_sequence(
    records: list[dict[str, Any]], methods: list[str], sequence: str, path: Path
) -> Path | None:
    """Recall vs 1-precision per pair of one sequence, one line per method (Figure 13 style)."""
    names = sorted({r["pair"] for r in records if r["sequence"] == sequence})
    if not names:
        return None
    cols = min(5, len(names))
    rows = (len(names) + cols - 1) // cols
    fig, axes = plt.subplots(rows, cols, figsize=(2.8 * cols, 2.7 * rows), squeeze=False)
    for ax, name in zip(axes.flat, names, strict=False):
        for m in methods:
            rs = _by(records, method=m, sequence=sequence, pair=name)
            if rs:
                _curve(ax, rs[0], m)
        _finish(ax, f"{sequence} {name}")
    for ax in list(axes.flat)[len(names) :]:
        ax.axis("off")
    axes.flat[0].legend(fontsize=6)
    return _save(fig, path)


def figure_pairs(pairs: list[Any], path: Path) -> Path | None:
    """Figure 15 style: image ``a`` of the first pair, then image ``b`` of each pair, with the
    pair names."""
    if not pairs:
        return None
    images = [("a", pairs[0].a)] + [(p.name, p.b) for p in pairs]
    fig, axes = plt.subplots(1, len(images), figsize=(2.4 * len(images), 2.1))
    for ax, (name, img) in zip(axes, images, strict=True):
        ax.imshow(img)
        ax.set_title(name, fontsize=9)
        ax.axis("off")
    return _save(fig, path)


def figure_real(
    records: list[dict[str, Any]], pairs: list[tuple[str, str]], sets: tuple[str, ...], path: Path
) -> Path | None:
    """Issue 17: recall at 1-precision 0.1 of each colour label against its grey base, one
    point per real illumination pair, one panel per set (above the diagonal: colour wins)."""
    present = [s for s in sets if _by(records, sequence=s)]
    pairs = [(c, g) for c, g in pairs if _by(records, method=c) and _by(records, method=g)]
    if not present or not pairs:
        return None
    fig, axes = plt.subplots(1, len(present), figsize=(3.3 * len(present), 3.4), squeeze=False)
    markers = "os^vDP*X"
    for ax, seq in zip(axes[0], present, strict=True):
        for k, (c, g) in enumerate(pairs):
            grey = {r["pair"]: r["recall_at_01"] for r in _by(records, method=g, sequence=seq)}
            pts = [
                (grey[r["pair"]], r["recall_at_01"])
                for r in _by(records, method=c, sequence=seq)
                if r["pair"] in grey
            ]
            if pts:
                x, y = zip(*pts, strict=True)
                ax.plot(x, y, markers[k % len(markers)], ms=3.5, alpha=0.7, label=f"{c} vs {g}")
        ax.plot([0, 1], [0, 1], "k--", lw=0.8)
        ax.set_xlim(0, 1)
        ax.set_ylim(0, 1)
        ax.set_xlabel("grey base recall@0.1")
        ax.set_ylabel("colour recall@0.1")
        ax.set_title(seq, fontsize=9)
        ax.grid(alpha=0.3)
    axes[0][0].legend(fontsize=6, loc="lower right")
    return _save(fig, path)
