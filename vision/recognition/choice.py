"""The outcome of the automatic threshold selection (chapter section 6), as a value.

:func:`vision.recognition.threshold.choose_threshold` computes it; recognition reads it.
Kept apart from the selection so that :mod:`vision.recognition.recognise` can read a choice
without importing the module that evaluates recognition to make one.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field, replace

import numpy as np

__all__ = ["ThresholdChoice", "roc_curve"]


@dataclass(frozen=True, eq=False)
class ThresholdChoice:
    """Thresholds chosen from the score distributions, with the figures used.

    Attributes
    ----------
    threshold : float
        Global threshold in [0, 1]; a model passes when its score is strictly above.
    per_model : mapping of str to float
        Threshold per model (each >= ``threshold``).
    rule : str
        Rule and figures in words (what was bounded, with how many scores).
    rule_id : str
        ``"conformal-far"`` or ``"youden"``.
    target_far : float or None
        Target false-accept rate (conformal rule).
    far_bound : float or None
        Finite-sample bound ``1 - k / (n + 1)`` achieved (conformal rule; ``None`` when too
        few impostor scores to bound it).
    far, frr : float
        Empirical false-accept rate on the impostor scores and false-reject rate on the
        genuine (leave-one-view-out) scores at ``threshold``.
    genuine, impostor : ndarray
        The score distributions (genuine per held-out view; impostor per held-out-model view
        and per negative image).
    genuine_models : tuple of str
        Model of each genuine score.
    confusion : mapping
        ``confusion[viewpoint][a][b]``: share of ``a``'s held-out views on which ``b`` scores
        above the viewpoint's candidate bar.
    candidate : float
        The rule on the impostor scores without twins (module docstring), at most
        ``threshold``: the bar for considering a model worth verifying with another view.
    per_viewpoint : mapping of int to float
        Global threshold of the rule on each viewpoint's scores alone.
    per_model_viewpoint : mapping of int to mapping of str to float
        Per-model thresholds of each viewpoint.
    candidate_viewpoint : mapping of int to float
        ``candidate`` of each viewpoint.
    own_viewpoint : mapping of int to mapping of str to float
        Per-model bars of each viewpoint from the model's own impostor scores alone, not
        raised to the viewpoint's threshold (each <= it); the global one where the model
        has too few scores (:func:`vision.recognition.choose_threshold`, "Own bars"). The
        multi-view policies apply them on side views and to shortlist from the top.
    advice : tuple of str
        What to add (views, models, negative images) when the data cannot support the
        target false-accept rate, in plain words; empty when it can.
    """

    threshold: float
    per_model: Mapping[str, float]
    rule: str
    rule_id: str
    target_far: float | None
    far_bound: float | None
    far: float
    frr: float
    genuine: np.ndarray
    impostor: np.ndarray
    genuine_models: tuple[str, ...]
    confusion: Mapping[int, Mapping[str, Mapping[str, float]]]
    candidate: float = 0.0
    per_viewpoint: Mapping[int, float] = field(default_factory=dict)
    per_model_viewpoint: Mapping[int, Mapping[str, float]] = field(default_factory=dict)
    candidate_viewpoint: Mapping[int, float] = field(default_factory=dict)
    own_viewpoint: Mapping[int, Mapping[str, float]] = field(default_factory=dict)
    advice: tuple[str, ...] = ()

    def at(self, viewpoint: int) -> ThresholdChoice:
        """The choice for one viewpoint (itself when that viewpoint has no thresholds)."""
        if viewpoint not in self.per_viewpoint:
            return self
        return replace(
            self,
            threshold=self.per_viewpoint[viewpoint],
            per_model=self.per_model_viewpoint.get(viewpoint, {}),
            candidate=self.candidate_viewpoint.get(viewpoint, self.candidate),
            per_viewpoint={},
            per_model_viewpoint={},
            candidate_viewpoint={},
            own_viewpoint={},
        )

    def own(self, model: str, viewpoint: int) -> float:
        """``model``'s own bar at ``viewpoint`` (``own_viewpoint``), else its per-model
        threshold there."""
        row = self.own_viewpoint.get(viewpoint)
        if row is not None and model in row:
            return float(row[model])
        at = self.at(viewpoint)
        return float(at.per_model.get(model, at.threshold))

    def roc(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(thresholds, far, tpr)`` over every observed score (accept when score > t)."""
        return roc_curve(self.genuine, self.impostor)


def roc_curve(
    genuine: np.ndarray, impostor: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """False-accept and true-accept rates at every distinct score (accept when score > t)."""
    g = np.sort(np.asarray(genuine, dtype=np.float64))
    i = np.sort(np.asarray(impostor, dtype=np.float64))
    t = np.unique(np.concatenate([[0.0], g, i, [1.0]]))
    far = 1.0 - np.searchsorted(i, t, side="right") / max(len(i), 1)
    tpr = 1.0 - np.searchsorted(g, t, side="right") / max(len(g), 1)
    return t, far, tpr
