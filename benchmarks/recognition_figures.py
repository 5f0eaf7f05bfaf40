"""Plots of the recognition benchmark (matplotlib, Agg canvas): accuracy against training-view
spacing, latency against index size, and the viewpoint policies."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure


def _fig(w: float = 5.0, h: float = 3.4) -> Figure:
    fig = Figure(figsize=(w, h))
    FigureCanvasAgg(fig)
    return fig


def accuracy_vs_spacing(closed: list[dict[str, Any]], path: Path) -> Path:
    """Top-1 accuracy of the view index, brute force and the eigenspace per spacing."""
    fig = _fig()
    ax = fig.subplots()
    x = [r["spacing_deg"] for r in closed]
    ax.plot(x, [100 * r["index_accuracy"] for r in closed], "o-", label="view index (ANN + verify)")
    ax.plot(
        x, [100 * r["eigenspace_accuracy"] for r in closed], "s--", label="eigenspace (PCA, NN)"
    )
    bf = [(r["spacing_deg"], r["brute_accuracy"]) for r in closed if r.get("brute_accuracy")]
    if bf:
        ax.plot(
            [b[0] for b in bf], [100 * b[1] for b in bf], "^:", label="brute-force registration"
        )
    ax.axhline(99, color="grey", lw=0.8, ls=":")
    ax.axhline(95, color="grey", lw=0.8, ls=":")
    ax.set_xlabel("training-view spacing (degrees)")
    ax.set_ylabel("top-1 correct (%)")
    ax.set_xticks(x)
    ax.set_title("COIL-20 objects 1-15, closed set", fontsize=10)
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    return path


def latency_vs_size(latency: list[dict[str, Any]], path: Path) -> Path:
    """Median latency per query against the number of trained views (log-log)."""
    fig = _fig()
    ax = fig.subplots()
    n = [r["views"] for r in latency]
    ax.loglog(n, [r["index_ms"] for r in latency], "o-", label="view index: retrieval + verify")
    ax.loglog(n, [r["brute_ms"] for r in latency], "^--", label="brute-force registration")
    ax.axhline(30, color="grey", lw=0.8, ls=":", label="30 ms target")
    ax.set_xlabel("trained views")
    ax.set_ylabel("median ms per query (after extraction)")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3, which="both")
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    return path


def policies(rows: list[dict[str, Any]], path: Path) -> Path:
    """Views visited and correct outcomes per viewpoint policy, one bar group per scenario."""
    fig = _fig(7.0, 3.0)
    ax1, ax2 = fig.subplots(1, 2)
    scen = list(dict.fromkeys(r["scenario"] for r in rows))
    pols = list(dict.fromkeys(r["policy"] for r in rows))
    width = 0.8 / len(scen)
    for i, sc in enumerate(scen):
        by = {r["policy"]: r for r in rows if r["scenario"] == sc}
        x = [j + (i - (len(scen) - 1) / 2) * width for j in range(len(pols))]
        ax1.bar(x, [by[p]["mean_views"] for p in pols], width, label=sc)
        ax2.bar(x, [100 * by[p]["accuracy"] for p in pols], width, label=sc)
    ax1.set_ylabel("mean views visited")
    ax2.set_ylabel("correct outcome (%)")
    ax2.set_ylim(max(0, min(100 * r["accuracy"] for r in rows) - 10), 100)
    for ax in (ax1, ax2):
        ax.set_xticks(range(len(pols)), pols)
        ax.tick_params(axis="x", labelsize=7, rotation=20)
        ax.grid(alpha=0.3, axis="y")
    ax1.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    return path
