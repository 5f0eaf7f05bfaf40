"""Plots of a threshold choice: the genuine and impostor score distributions, and the ROC.

Drawn with matplotlib's object API on an Agg canvas (no global backend, no display), so it
runs in servers and tests alike.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from vision.recognition.threshold import ThresholdChoice

__all__ = ["plot_threshold"]


def plot_threshold(
    choice: ThresholdChoice,
    path: str | Path,
    *,
    title: str | None = None,
    unknown: np.ndarray | None = None,
    dpi: int = 90,
) -> Path:
    """Write a PNG with the score histograms (left) and the ROC (right) of ``choice``.

    Parameters
    ----------
    choice : ThresholdChoice
        From :func:`vision.recognition.choose_threshold`.
    path : str or Path
        Output PNG; its folder is created.
    title : str, optional
    unknown : ndarray of shape (N,), optional
        Best scores of truly unknown objects measured afterwards (drawn as a third
        histogram, not used by the choice).
    dpi : int
        Resolution, 30..300.

    Returns
    -------
    Path
        The written file.
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    if not isinstance(choice, ThresholdChoice):
        raise ValueError(f"choice must be a ThresholdChoice, got {type(choice).__name__}")
    if isinstance(dpi, bool) or not isinstance(dpi, int) or not 30 <= dpi <= 300:
        raise ValueError(f"dpi must be an int in 30..300, got {dpi!r}")
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig = Figure(figsize=(9.0, 3.6))
    FigureCanvasAgg(fig)
    ax, roc = fig.subplots(1, 2)
    bins = np.linspace(0.0, 1.0, 41)
    ax.hist(
        choice.genuine, bins=bins, alpha=0.6, density=True, label="genuine (leave-one-view-out)"
    )
    ax.hist(
        choice.impostor, bins=bins, alpha=0.6, density=True, label="impostor (leave-one-model-out)"
    )
    if unknown is not None and len(unknown):
        ax.hist(
            np.asarray(unknown),
            bins=bins,
            histtype="step",
            lw=1.5,
            density=True,
            color="k",
            label="unknown objects (test)",
        )
    ax.axvline(choice.threshold, color="r", ls="--", label=f"threshold {choice.threshold:.3f}")
    ax.set_xlabel("score")
    ax.set_ylabel("density")
    ax.set_yscale("symlog", linthresh=1.0)
    ax.legend(fontsize=7)
    _, far, tpr = choice.roc()
    roc.plot(far, tpr, lw=1.5)
    roc.plot(
        [choice.far],
        [1.0 - choice.frr],
        "ro",
        label=f"chosen: FAR {choice.far:.3f}, TAR {1 - choice.frr:.3f}",
    )
    roc.set_xscale("symlog", linthresh=1e-2)
    roc.set_xlim(0.0, 1.0)
    roc.set_ylim(0.0, 1.02)
    roc.set_xlabel("false-accept rate")
    roc.set_ylabel("true-accept rate")
    roc.legend(fontsize=7, loc="lower right")
    roc.grid(alpha=0.3)
    if title:
        fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=dpi)
    return path
