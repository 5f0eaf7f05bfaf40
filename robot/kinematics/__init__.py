"""Kinematics of the ASEA arm: forward (chapter eq. 20) and inverse."""

from robot.kinematics.forward import R_base_ee, T_base_ee, check_q, fk, joint_positions

__all__ = ["R_base_ee", "T_base_ee", "check_q", "fk", "joint_positions"]
