"""Server-side PNG plots of the reports (matplotlib, Agg): throughput per bucket, cycle-time
percentiles and the stage breakdown, score histograms per model, the confusion matrix.

Each function takes the dict the corresponding query returns (:mod:`backend.reports.queries`)
and writes one PNG; nothing here touches the database.
"""

from __future__ import annotations

import itertools
from pathlib import Path
from typing import Any

__all__ = ["plot_all", "plot_confusion", "plot_cycle", "plot_scores", "plot_throughput"]

_COLOURS = {"recognized": "#2e7d32", "unknown": "#f9a825", "failed": "#c62828"}


def _plt() -> Any:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def plot_throughput(ts: dict[str, Any], path: Path) -> Path:
    """Stacked bars of inspections per bucket by decision, and the median cycle time."""
    plt = _plt()
    data = ts["data"]
    fig, ax = plt.subplots(figsize=(9, 3.6), dpi=100)
    x = list(range(len(data)))
    bottom = [0] * len(data)
    for d in ("recognized", "unknown", "failed"):
        h = [b[d] for b in data]
        ax.bar(x, h, bottom=bottom, color=_COLOURS[d], label=d, width=0.9)
        bottom = [a + b for a, b in zip(bottom, h, strict=True)]
    ax.set_ylabel(f"inspections per {ts['bucket']}")
    step = max(1, len(data) // 8)
    ax.set_xticks(x[::step], [b["t"][5:16].replace("T", " ") for b in data][::step], fontsize=7,
                  rotation=30, ha="right")  # fmt: skip
    ax.legend(loc="upper left", fontsize=8)
    if data:
        ax2 = ax.twinx()
        ax2.plot(x, [b["cycle_p50"] for b in data], color="#1565c0", lw=1.0, label="median cycle")
        ax2.set_ylabel("median cycle time, s", color="#1565c0")
    ax.set_title(f"Throughput per {ts['bucket']} (UTC)")
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
    return path


def plot_cycle(summary: dict[str, Any], path: Path) -> Path:
    """Cycle-time percentiles (left) and the per-stage mean with its p95 (right)."""
    plt = _plt()
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(10, 3.6), dpi=100)
    keys = ["p50", "p95", "p99", "mean", "max"]
    vals = [summary["cycle_s"][k] or 0.0 for k in keys]
    a1.bar(keys, vals, color="#546e7a")
    for i, v in enumerate(vals):
        a1.text(i, v, f"{v:.2f}", ha="center", va="bottom", fontsize=8)
    a1.set_ylabel("cycle time, s")
    a1.set_title(f"Cycle time ({summary['count']} inspections)")
    st = summary["stages"]
    names = list(st)
    a2.barh(names, [st[n]["mean"] for n in names], color="#78909c", label="mean")
    a2.scatter([st[n]["p95"] for n in names], names, color="#c62828", marker="|", s=120,
               label="p95")  # fmt: skip
    a2.invert_yaxis()
    a2.set_xlabel("seconds")
    a2.set_title("Stage breakdown")
    a2.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
    return path


def plot_scores(summary: dict[str, Any], path: Path) -> Path:
    """One score histogram per model (small multiples)."""
    plt = _plt()
    models = summary["per_model"] or [{"model": "(none)", "count": 0,
                                       "hist": {"edges": [i / 10 for i in range(11)], "counts": [0] * 10}}]  # fmt: skip
    cols = min(3, len(models))
    rows = -(-len(models) // cols)
    fig, axes = plt.subplots(rows, cols, figsize=(3.4 * cols, 2.4 * rows), dpi=100, squeeze=False)
    for ax in axes.flat:
        ax.set_visible(False)
    for ax, m in zip(axes.flat, models, strict=False):
        ax.set_visible(True)
        e, c = m["hist"]["edges"], m["hist"]["counts"]
        ax.bar(e[:-1], c, width=[b - a for a, b in itertools.pairwise(e)], align="edge",
               color="#2e7d32", edgecolor="white")  # fmt: skip
        ax.set_xlim(0, 1)
        ax.set_title(f"{m['model']} (n={m['count']})", fontsize=9)
        ax.set_xlabel("score", fontsize=8)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
    return path


def plot_confusion(cf: dict[str, Any], path: Path) -> Path:
    """The confusion matrix (rows: truth, columns: decided label) with its counts."""
    plt = _plt()
    import numpy as np

    m = np.asarray(cf["matrix"], dtype=float).reshape(len(cf["truth"]), len(cf["labels"]))
    fig, ax = plt.subplots(figsize=(1.2 + 0.8 * len(cf["labels"]), 1.2 + 0.6 * max(1, len(cf["truth"]))), dpi=100)  # fmt: skip
    ax.imshow(m if m.size else np.zeros((1, 1)), cmap="Blues", aspect="auto")
    ax.set_xticks(range(len(cf["labels"])), cf["labels"], rotation=45, ha="right", fontsize=8)
    ax.set_yticks(range(len(cf["truth"])), cf["truth"], fontsize=8)
    for i in range(m.shape[0]):
        for j in range(m.shape[1]):
            if m[i, j]:
                ax.text(j, i, f"{int(m[i, j])}", ha="center", va="center", fontsize=7,
                        color="white" if m[i, j] > m.max() / 2 else "black")  # fmt: skip
    ax.set_xlabel("decided")
    ax.set_ylabel("truth (simulator)")
    ax.set_title(f"Confusion ({cf['count']} inspections with truth)")
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
    return path


def plot_all(summary: dict[str, Any], ts: dict[str, Any], cf: dict[str, Any], folder: Path) -> list[Path]:  # fmt: skip
    """Write the four plots into ``folder`` (created); returns their paths."""
    folder.mkdir(parents=True, exist_ok=True)
    return [
        plot_throughput(ts, folder / "throughput.png"),
        plot_cycle(summary, folder / "cycle_time.png"),
        plot_scores(summary, folder / "scores.png"),
        plot_confusion(cf, folder / "confusion.png"),
    ]
