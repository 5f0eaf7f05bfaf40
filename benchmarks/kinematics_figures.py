"""Figures of the kinematics benchmark: the chapter's Figures 9 and 17, and GA convergence."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from robot.kinematics.fuzzy import INPUTS, MF_LABELS
from robot.kinematics.fuzzy_protocol import CHAPTER, ProtocolReport

__all__ = ["plot_figure9_mfs", "plot_figure17_sse", "plot_ga_convergence"]


def plot_figure17_sse(reports: list[ProtocolReport], path: Path) -> Path:
    """SSE in the joints per test pose (the chapter's Figure 17), one panel per region."""
    fig, axes = plt.subplots(len(reports), 1, figsize=(8, 3.2 * len(reports)), squeeze=False)
    for ax, rep in zip(axes[:, 0], reports, strict=True):
        e = rep.test_sse_per_pose
        ax.bar(np.arange(1, e.size + 1), e, color="tab:blue", label="this run")
        ax.axhline(
            CHAPTER.test_sse_per_pose_max,
            color="tab:red",
            ls="--",
            label=f"chapter's upper bound {CHAPTER.test_sse_per_pose_max:g}",
        )
        ax.set_yscale("log")
        ax.set_xlabel("test pose")
        ax.set_ylabel("SSE in q1..q5 (rad$^2$)")
        ax.set_title(f"{rep.region.name}: {e.size} random test poses, max {e.max():.3g}")
        ax.legend(loc="best", fontsize=8, framealpha=0.9)
    fig.suptitle("Sugeno fuzzy IK after GA tuning (cf. chapter Figure 17)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def plot_figure9_mfs(rep: ProtocolReport, path: Path) -> Path:
    """Antecedent MFs before (dashed) and after GA tuning (the chapter's Figure 9)."""
    fig, axes = plt.subplots(1, 5, figsize=(15, 3.0))
    lo, hi = rep.initial.mean[:, 0], rep.initial.mean[:, 1]
    for i, ax in enumerate(axes):
        pad = 0.5 * (hi[i] - lo[i])
        v = np.linspace(lo[i] - pad, hi[i] + pad, 300)
        for lab, color in zip(range(2), ("tab:blue", "tab:orange"), strict=True):
            for fis, style in ((rep.initial, "--"), (rep.fis, "-")):
                m, s = fis.mean[i, lab], fis.sigma[i, lab]
                ax.plot(v, np.exp(-0.5 * ((v - m) / s) ** 2), style, color=color, lw=1.4)
        ax.set_title(f"input {INPUTS[i]}")
        ax.set_ylim(0, 1.05)
        ax.set_xlabel(INPUTS[i] + (" (m)" if i < 3 else ""))
    axes[0].set_ylabel("membership")
    axes[0].legend(
        [
            plt.Line2D([], [], color="tab:blue"),
            plt.Line2D([], [], color="tab:orange"),
            plt.Line2D([], [], color="k", ls="--"),
        ],
        [*MF_LABELS, "before tuning"],
        fontsize=8,
    )
    fig.suptitle(f"Antecedent MFs after GA tuning, {rep.region.name} (cf. chapter Figure 9)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def plot_ga_convergence(reports: list[ProtocolReport], path: Path) -> Path:
    """Best and mean training SSE per GA cycle."""
    fig, ax = plt.subplots(figsize=(7, 3.6))
    for rep, color in zip(reports, ("tab:blue", "tab:green"), strict=False):
        g = np.arange(rep.ga.best_sse_history.size)
        ax.plot(g, rep.ga.best_sse_history, color=color, label=f"{rep.region.name}: best")
        ax.plot(g, rep.ga.mean_sse_history, color=color, ls=":", label="population mean")
    ax.axhline(CHAPTER.sse_after, color="tab:red", ls="--", label="chapter after 50 cycles")
    ax.set_yscale("log")
    ax.set_xlabel("GA cycle")
    ax.set_ylabel("training SSE over 100 poses (rad$^2$)")
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
