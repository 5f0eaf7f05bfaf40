"""Kinematics of the ASEA arm: forward (chapter eq. 20) and inverse.

* :func:`fk`, :func:`T_base_ee`, :func:`joint_positions`: eq. 20 and the full flange pose.
* :func:`ik`, :func:`ik_solutions`, :func:`ik_batch`: the exact closed-form inverse.
* :func:`ik_pose`: a 6-DOF target projected onto what the 5-DOF arm reaches.
* :func:`hybrid_ik`, :func:`hybrid_ik_batch`: the chapter's section 3.6.1 loop (an IK
  estimate corrected through FK).
* :class:`SugenoIK`, :func:`tune_consequents`, :func:`tune_antecedents`,
  :func:`run_chapter_protocol`: the chapter's section 3.6.3 fuzzy inverse (eqs. 21-23) and
  its section 4.4 protocol.
"""

from robot.kinematics.analytic import BRANCHES, IKSolution, check_pose, ik, ik_solutions
from robot.kinematics.batch import ik_batch
from robot.kinematics.forward import R_base_ee, T_base_ee, check_q, fk, joint_positions
from robot.kinematics.fuzzy import SugenoIK, initial_sugeno, tune_consequents
from robot.kinematics.fuzzy_ga import GAConfig, GATuning, tune_antecedents
from robot.kinematics.fuzzy_protocol import (
    CHAPTER,
    STATION_REGION,
    WORKSPACE_REGION,
    PoseRegion,
    ProtocolReport,
    run_chapter_protocol,
    sample_poses,
)
from robot.kinematics.hybrid import (
    HybridBatchResult,
    HybridIKResult,
    fuzzy_estimator,
    hybrid_ik,
    hybrid_ik_batch,
    nominal_model_estimator,
)
from robot.kinematics.pose6 import IKPoseResult, ik_pose

__all__ = [
    "BRANCHES",
    "CHAPTER",
    "STATION_REGION",
    "WORKSPACE_REGION",
    "GAConfig",
    "GATuning",
    "HybridBatchResult",
    "HybridIKResult",
    "IKPoseResult",
    "IKSolution",
    "PoseRegion",
    "ProtocolReport",
    "R_base_ee",
    "SugenoIK",
    "T_base_ee",
    "check_pose",
    "check_q",
    "fk",
    "fuzzy_estimator",
    "hybrid_ik",
    "hybrid_ik_batch",
    "ik",
    "ik_batch",
    "ik_pose",
    "ik_solutions",
    "initial_sugeno",
    "joint_positions",
    "nominal_model_estimator",
    "run_chapter_protocol",
    "sample_poses",
    "tune_antecedents",
    "tune_consequents",
]
