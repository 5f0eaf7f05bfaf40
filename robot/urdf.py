"""A URDF description of the arm, generated from :class:`robot.model.ArmModel`.

The chain reproduces eq. 20 and the flange frame of :mod:`robot.kinematics.forward`:

* ``joint1`` (q1) about the base z axis at the origin;
* ``joint2``, ``joint3``, ``joint4`` (q2, q3, q4) about ``-y`` of their parents, so that a
  positive angle raises the link from the horizontal (``Ry(-q) e_x = (cos q, 0, sin q)``); the
  shoulder sits ``L1`` above the base, the elbow ``L2`` and the wrist ``L3`` along ``x``;
* ``joint5`` (q5) ``L4 + L5`` further along ``x``, turned by ``rpy = (0, pi/2, 0)`` so that
  its z axis, the roll axis, is the approach direction; the child link ``flange`` is the
  ``ee`` frame: ``T_base_flange = Rz(q1) Ry(pi/2 - phi) Rz(q5)`` with ``phi = q2 + q3 + q4``.

Link visuals are plain cylinders (for a 3D view); masses are nominal, for tools that insist
on inertials.  Joint limits and velocity limits come from the model.
"""

from __future__ import annotations

import math
from xml.sax.saxutils import quoteattr

from robot.model import ASEA, ArmModel

__all__ = ["urdf_from_model"]


def _f(v: float) -> str:
    return repr(float(v))


def _link(name: str, length: float, axis: str, radius: float) -> str:
    """A link with a cylinder of ``length`` along ``axis`` ('x' or 'z') from its origin."""
    if length <= 0:
        return f'  <link name="{name}"/>\n'
    if axis == "z":
        origin = f'<origin xyz="0 0 {_f(length / 2)}" rpy="0 0 0"/>'
    else:  # a cylinder's own axis is z: turn it onto x
        origin = f'<origin xyz="{_f(length / 2)} 0 0" rpy="0 {_f(math.pi / 2)} 0"/>'
    geom = f'<geometry><cylinder radius="{_f(radius)}" length="{_f(length)}"/></geometry>'
    return (
        f'  <link name="{name}">\n'
        f"    <visual>{origin}{geom}"
        '<material name="arm"><color rgba="0.85 0.45 0.1 1"/></material></visual>\n'
        f'    <inertial>{origin}<mass value="1.0"/>'
        '<inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.01"/></inertial>\n'
        "  </link>\n"
    )


def _joint(
    name: str,
    parent: str,
    child: str,
    xyz: tuple[float, float, float],
    rpy: tuple[float, float, float],
    axis: tuple[float, float, float],
    limits: tuple[float, float],
    velocity: float,
) -> str:
    return (
        f'  <joint name="{name}" type="revolute">\n'
        f'    <parent link="{parent}"/><child link="{child}"/>\n'
        f'    <origin xyz="{" ".join(_f(v) for v in xyz)}" rpy="{" ".join(_f(v) for v in rpy)}"/>\n'
        f'    <axis xyz="{" ".join(_f(v) for v in axis)}"/>\n'
        f'    <limit lower="{_f(limits[0])}" upper="{_f(limits[1])}" effort="1000" '
        f'velocity="{_f(velocity)}"/>\n'
        "  </joint>\n"
    )


def urdf_from_model(model: ArmModel = ASEA, *, robot_name: str = "asea") -> str:
    """URDF XML text of ``model`` (module docstring for the frames).

    Parameters
    ----------
    model : ArmModel
        Link lengths (Table 1), joint ranges and velocity limits.
    robot_name : str
        The ``<robot name=...>`` attribute.

    Returns
    -------
    str
        A URDF document with links ``base_link``, ``column``, ``upper_arm``, ``forearm``,
        ``wrist``, ``flange`` and revolute joints ``joint1`` .. ``joint5``.
    """
    L1, L2, L3, L45 = model.L1, model.L2, model.L3, model.L45
    lim = [(float(a), float(b)) for a, b in model.joint_limits_rad]
    vel = [float(v) for v in model.max_velocity_rad_s]
    down = (0.0, -1.0, 0.0)
    parts = [
        '<?xml version="1.0"?>\n',
        f"<robot name={quoteattr(robot_name)}>\n",
        '  <link name="base_link"/>\n',
        _link("column", L1, "z", 0.09),
        _link("upper_arm", L2, "x", 0.06),
        _link("forearm", L3, "x", 0.05),
        _link("wrist", L45, "x", 0.04),
        '  <link name="flange"/>\n',
        _joint("joint1", "base_link", "column", (0, 0, 0), (0, 0, 0), (0, 0, 1), lim[0], vel[0]),
        _joint("joint2", "column", "upper_arm", (0, 0, L1), (0, 0, 0), down, lim[1], vel[1]),
        _joint("joint3", "upper_arm", "forearm", (L2, 0, 0), (0, 0, 0), down, lim[2], vel[2]),
        _joint("joint4", "forearm", "wrist", (L3, 0, 0), (0, 0, 0), down, lim[3], vel[3]),
        _joint(
            "joint5", "wrist", "flange", (L45, 0, 0), (0, math.pi / 2, 0), (0, 0, 1), lim[4], vel[4]
        ),
        "</robot>\n",
    ]
    return "".join(parts)
