"""Descriptor evaluation (chapter section 4.2, equations 24-25): the protocol of Mikolajczyk
and Schmid (PAMI 2005) with region-overlap ground truth, recall versus 1-precision curves and
their summaries, and the chapter's studies (Figures 12, 14 and 16)."""

from vision.evaluation.protocol import (
    STRATEGIES,
    PairEvaluation,
    RecallCurve,
    common_part,
    correspondences,
    curve_from_matches,
    evaluate_pair,
)
from vision.evaluation.regions import (
    Overlaps,
    apply_homography,
    ellipse_matrices,
    ellipse_overlap_error,
    overlap_errors,
    project_regions,
)

__all__ = [
    "STRATEGIES",
    "Overlaps",
    "PairEvaluation",
    "RecallCurve",
    "apply_homography",
    "common_part",
    "correspondences",
    "curve_from_matches",
    "ellipse_matrices",
    "ellipse_overlap_error",
    "evaluate_pair",
    "overlap_errors",
    "project_regions",
]
