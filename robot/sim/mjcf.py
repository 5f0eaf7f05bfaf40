"""The MJCF of the simulated cell, generated in code from :data:`robot.model.ASEA`.

The arm's kinematic chain reproduces chapter eq. 20 and the flange frame of
:func:`robot.kinematics.T_base_ee` exactly (tests check both to 1e-9):

* ``column`` turns about the base z axis (q1);
* ``upper_arm`` at height L1, ``forearm`` at L2 along it and ``wrist`` at L3 along that
  pitch about the axis ``-y`` of the column frame (q2, q3, q4), so that a positive angle
  raises the link and every link lies along its body's +x at zero angle;
* ``flange`` sits L4 + L5 along the wrist, turned by +90 deg about y so that its z axis is
  the approach direction, and rolls about it (q5).

Each joint has a torque motor (the chapter's Figure 8: torques in, angles and velocities
out), a reflected rotor inertia (``armature``), viscous damping and dry friction.  Link
masses and sizes are plausible for an ASEA IRB 6-class arm; the chapter gives none.  Every
geom is visual only (no contacts): the cell's parts never touch each other.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from typing import TYPE_CHECKING

import mujoco
import numpy as np

from robot.model import ASEA, ArmModel
from robot.sim.boards import add_board_body
from robot.sim.builder import MjcfBuilder, fmt, quat_from_matrix
from robot.sim.camera import CameraSpec, Lens
from robot.sim.catalogue import CATALOGUE
from robot.sim.gripper import SuctionCupSpec
from robot.sim.world import WorldLayout, add_world

if TYPE_CHECKING:
    from robot.sim.config import SimConfig

__all__ = [
    "JOINT_NAMES",
    "ArmDynamics",
    "CellModel",
    "add_arm",
    "add_suction_cup",
    "build_cell",
]

JOINT_NAMES = ("q1", "q2", "q3", "q4", "q5")
#: Sites on the chain, in the order of :func:`robot.kinematics.joint_positions` rows 1-4.
CHAIN_SITES = ("shoulder", "elbow", "wrist", "flange")


@dataclass(frozen=True)
class ArmDynamics:
    """Mass properties and drive parameters of the simulated arm (SI units).

    Attributes
    ----------
    link_mass_kg : tuple of 5 floats
        Column, upper arm, forearm, wrist, flange with camera.
    armature_kg_m2 : tuple of 5 floats
        Motor rotor inertia reflected through the gearbox, per joint.
    damping_n_m_s : tuple of 5 floats
        Viscous joint friction, N m s/rad.
    friction_n_m : tuple of 5 floats
        Dry (Coulomb) joint friction, N m.
    torque_limit_n_m : tuple of 5 floats
        Motor torque limits.
    hard_stop_margin_rad : float
        Mechanical stops sit this far outside the software joint ranges.
    """

    link_mass_kg: tuple[float, ...] = (35.0, 18.0, 9.0, 2.0, 1.2)
    armature_kg_m2: tuple[float, ...] = (4.0, 4.0, 2.0, 0.3, 0.05)
    damping_n_m_s: tuple[float, ...] = (6.0, 6.0, 4.0, 0.6, 0.1)
    friction_n_m: tuple[float, ...] = (3.0, 3.0, 2.0, 0.4, 0.1)
    torque_limit_n_m: tuple[float, ...] = (700.0, 1000.0, 500.0, 120.0, 40.0)
    hard_stop_margin_rad: float = math.radians(3.0)

    def __post_init__(self) -> None:
        for name in (
            "link_mass_kg",
            "armature_kg_m2",
            "damping_n_m_s",
            "friction_n_m",
            "torque_limit_n_m",
        ):
            v = getattr(self, name)
            if len(v) != 5 or any(not (x >= 0 and math.isfinite(x)) for x in v):
                raise ValueError(f"{name} must be 5 finite values >= 0, got {v!r}")
        if any(x <= 0 for x in self.torque_limit_n_m) or any(x <= 0 for x in self.link_mass_kg):
            raise ValueError("link masses and torque limits must be positive")


@dataclass(frozen=True)
class CellModel:
    """The generated MJCF and the names the engine needs.

    Attributes
    ----------
    xml : str
        The MJCF document.
    assets : dict of str to bytes
        In-memory files it references (PNG textures).
    slot_bodies : dict of str to tuple of str
        Mocap bodies available for each catalogue entry.
    cleat_bodies : tuple of str
        Mocap bodies of the belt's stripes.
    board_bodies : dict of str to str
        Mocap body per board kind.
    """

    xml: str
    assets: dict[str, bytes]
    slot_bodies: dict[str, tuple[str, ...]]
    cleat_bodies: tuple[str, ...]
    board_bodies: dict[str, str]

    def compile(self) -> mujoco.MjModel:
        """Compile with MuJoCo."""
        return mujoco.MjModel.from_xml_string(self.xml, self.assets)


def _joint(
    body: ET.Element, name: str, axis: str, lo: float, hi: float, i: int, dyn: ArmDynamics
) -> None:
    m = dyn.hard_stop_margin_rad
    ET.SubElement(
        body,
        "joint",
        name=name,
        type="hinge",
        axis=axis,
        range=fmt((lo - m, hi + m)),
        armature=f"{dyn.armature_kg_m2[i]:g}",
        damping=f"{dyn.damping_n_m_s[i]:g}",
        frictionloss=f"{dyn.friction_n_m[i]:g}",
    )


def add_arm(
    b: MjcfBuilder, model: ArmModel, dyn: ArmDynamics, camera: CameraSpec, lens: Lens
) -> ET.Element:
    """The arm's bodies, joints, motors, chain sites and the eye-in-hand camera; returns
    the flange body (tools are added to it)."""
    L1, L2, L3, L45, L5 = model.L1, model.L2, model.L3, model.L45, model.link_lengths_m[4]
    lo, hi = model.lower, model.upper
    mass = dyn.link_mass_kg
    b.material("asea", rgba=(0.93, 0.47, 0.12, 1), specular=0.4, shininess=0.4)
    b.material("motor", rgba=(0.22, 0.23, 0.25, 1), specular=0.5, shininess=0.5)
    b.material("flange", rgba=(0.7, 0.72, 0.75, 1), specular=0.7, shininess=0.6)
    b.material("camera", rgba=(0.08, 0.08, 0.09, 1), specular=0.6, shininess=0.6)
    b.material("glass", rgba=(0.15, 0.25, 0.4, 1), specular=1.0, shininess=0.9)
    vg = b.visual_geom
    vg(
        b.worldbody,
        name="base",
        type="cylinder",
        size="0.22 0.04",
        pos="0 0 0.04",
        material="motor",
    )
    column = ET.SubElement(b.worldbody, "body", name="column", pos="0 0 0")
    _joint(column, "q1", "0 0 1", lo[0], hi[0], 0, dyn)
    vg(
        column,
        type="cylinder",
        fromto=fmt((0, 0, 0.08, 0, 0, L1 - 0.09)),
        size="0.12",
        material="asea",
        mass=f"{mass[0] * 0.85:g}",
    )
    vg(
        column,
        type="box",
        size="0.09 0.11 0.09",
        pos=fmt((0, 0, L1)),
        material="asea",
        mass=f"{mass[0] * 0.15:g}",
    )
    ET.SubElement(column, "site", name="shoulder", pos=fmt((0, 0, L1)), size="0.01")
    upper = ET.SubElement(column, "body", name="upper_arm", pos=fmt((0, 0, L1)))
    _joint(upper, "q2", "0 -1 0", lo[1], hi[1], 1, dyn)
    vg(
        upper,
        type="cylinder",
        size="0.085 0.13",
        euler=fmt((math.pi / 2, 0, 0)),
        material="motor",
        mass=f"{mass[1] * 0.15:g}",
    )
    vg(
        upper,
        type="box",
        size=fmt((L2 / 2, 0.055, 0.065)),
        pos=fmt((L2 / 2, 0, 0)),
        material="asea",
        mass=f"{mass[1] * 0.85:g}",
    )
    forearm = ET.SubElement(upper, "body", name="forearm", pos=fmt((L2, 0, 0)))
    _joint(forearm, "q3", "0 -1 0", lo[2], hi[2], 2, dyn)
    ET.SubElement(forearm, "site", name="elbow", pos="0 0 0", size="0.01")
    vg(
        forearm,
        type="cylinder",
        size="0.07 0.1",
        euler=fmt((math.pi / 2, 0, 0)),
        material="motor",
        mass=f"{mass[2] * 0.2:g}",
    )
    vg(
        forearm,
        type="box",
        size=fmt((L3 / 2, 0.045, 0.05)),
        pos=fmt((L3 / 2, 0, 0)),
        material="asea",
        mass=f"{mass[2] * 0.8:g}",
    )
    wrist = ET.SubElement(forearm, "body", name="wrist", pos=fmt((L3, 0, 0)))
    _joint(wrist, "q4", "0 -1 0", lo[3], hi[3], 3, dyn)
    ET.SubElement(wrist, "site", name="wrist", pos="0 0 0", size="0.01")
    vg(
        wrist,
        type="cylinder",
        size="0.05 0.07",
        euler=fmt((math.pi / 2, 0, 0)),
        material="motor",
        mass=f"{mass[3] * 0.5:g}",
    )
    vg(
        wrist,
        type="cylinder",
        fromto=fmt((0, 0, 0, L45 - L5, 0, 0)),
        size="0.04",
        material="asea",
        mass=f"{mass[3] * 0.5:g}",
    )
    # Flange frame = T_base_ee: z along the approach direction (wrist +x), roll q5 about it.
    flange = ET.SubElement(
        wrist,
        "body",
        name="flange",
        pos=fmt((L45, 0, 0)),
        quat=fmt((math.cos(math.pi / 4), 0, math.sin(math.pi / 4), 0)),
    )
    _joint(flange, "q5", "0 0 1", lo[4], hi[4], 4, dyn)
    ET.SubElement(flange, "site", name="flange", pos="0 0 0", size="0.01")
    vg(
        flange,
        type="cylinder",
        fromto=fmt((0, 0, -L5, 0, 0, 0)),
        size="0.05",
        material="flange",
        mass=f"{mass[4] * 0.6:g}",
    )
    # The camera: MuJoCo cameras look along their -z with y up; OpenCV's look along +z with
    # y down, so R_flange_mjcam = R_ee_cam @ diag(1, -1, -1).
    T = camera.T_ee_cam
    R_mj = T[:3, :3] @ np.diag([1.0, -1.0, -1.0])
    ET.SubElement(
        flange,
        "camera",
        name="eye",
        mode="fixed",
        pos=fmt(T[:3, 3]),
        quat=fmt(quat_from_matrix(R_mj)),
        fovy=f"{lens.ideal_fovy_deg:.12g}",
    )
    z_cam = T[:3, 2]
    quat_cam = fmt(quat_from_matrix(T[:3, :3]))  # geoms along the optical axis (their z)
    vg(
        flange,
        type="box",
        size="0.028 0.028 0.024",
        pos=fmt(T[:3, 3] - 0.045 * z_cam),
        quat=quat_cam,
        material="camera",
        mass=f"{mass[4] * 0.3:g}",
    )
    vg(
        flange,
        type="cylinder",
        size="0.016 0.01",
        pos=fmt(T[:3, 3] - 0.012 * z_cam),
        quat=quat_cam,
        material="glass",
        mass=f"{mass[4] * 0.1:g}",
    )
    vg(
        flange,
        type="box",
        size="0.015 0.03 0.015",
        pos=fmt((T[0, 3] / 2, 0, 0.0)),
        material="flange",
        mass="0.01",
    )
    for i, name in enumerate(JOINT_NAMES):
        ET.SubElement(
            b.actuator,
            "motor",
            name=f"motor_{name}",
            joint=name,
            gear="1",
            ctrlrange=fmt((-dyn.torque_limit_n_m[i], dyn.torque_limit_n_m[i])),
        )
    return flange


def add_suction_cup(b: MjcfBuilder, flange: ET.Element, cup: SuctionCupSpec) -> None:
    """The suction cup beside the camera (bracket, tube, bellows, lip) and the ``payload``
    body at its lip that carries a gripped part's mass (see :mod:`robot.sim.gripper`)."""
    T = cup.T_ee_cup
    p, z = T[:3, 3], T[:3, 2]
    quat = fmt(quat_from_matrix(T[:3, :3]))
    b.material("cup", rgba=(0.12, 0.12, 0.13, 1), specular=0.2, shininess=0.2)
    b.material("tube", rgba=(0.75, 0.77, 0.8, 1), specular=0.6, shininess=0.5)
    vg = b.visual_geom
    base = p - (p @ z) * z  # where the cup's axis meets the flange face
    half = max(float(np.linalg.norm(base)) / 2.0, 0.012)  # bracket along x_ee
    vg(
        flange,
        type="box",
        size=fmt((half, 0.012, 0.01)),
        pos=fmt(base / 2 + 0.01 * z),
        material="tube",
    )
    vg(
        flange,
        type="cylinder",
        fromto=fmt((*(base + 0.01 * z), *(p - 0.025 * z))),
        size="0.008",
        material="tube",
        mass="0.05",
    )
    vg(
        flange,
        type="cylinder",
        fromto=fmt((*(p - 0.025 * z), *(p - 0.008 * z))),
        size=f"{0.7 * cup.radius_m:.6g}",
        material="cup",
        mass="0.02",
    )
    vg(
        flange,
        type="cylinder",
        fromto=fmt((*(p - 0.008 * z), *p)),
        size=f"{cup.radius_m:.6g}",
        material="cup",
        mass="0.01",
    )
    payload = ET.SubElement(flange, "body", name="payload", pos=fmt(p), quat=quat)
    ET.SubElement(payload, "inertial", pos="0 0 0", mass="1e-6", diaginertia="1e-9 1e-9 1e-9")


def texture_tint(layout: WorldLayout) -> float:
    """Grey level of a textured catalogue material's ``rgba``: the lighting of a face at the
    layout's default lights stays below MuJoCo's clamp.

    MuJoCo's renderer lights a textured face with the material's ``rgba`` as its colour,
    clamps the sum of the ambient and every light's terms at 1 and only then multiplies by
    the texture.  At full ``rgba`` a face lit by more than 1 in all rendered as if lit by 1,
    so the picture did not scale with the light: the valve block's top face under half light
    was 1/1.38 of its normal level while the belt (untextured: its colour enters the sum
    before the clamp) was 1/2, and a dimmer light changed the shading between the part's
    faces, which no gain undoes.  The bound is the headlight's ambient plus every lamp's
    diffuse (the most a face can receive); a tint of its inverse keeps the sum below 1 at
    the default intensities and dimmer, so a textured part scales with the light as the
    belt does.  Lights raised above their defaults can reach the clamp again."""
    bound = layout.ambient + sum(spec.diffuse for spec in layout.lights)
    return min(1.0, 1.0 / bound) if bound > 0 else 1.0


def _add_catalogue(b: MjcfBuilder, slots: int, layout: WorldLayout) -> dict[str, tuple[str, ...]]:
    out = {}
    tint = texture_tint(layout)
    for name, entry in CATALOGUE.items():
        geo = entry.geometry()
        mats = {}
        for key, mat in geo.materials.items():
            tex = b.texture(f"{name}_{key}", mat.texture) if mat.texture is not None else None
            rgba = mat.rgba
            if tex is not None:
                rgba = (mat.rgba[0] * tint, mat.rgba[1] * tint, mat.rgba[2] * tint, mat.rgba[3])
            mats[key] = b.material(
                f"{name}_{key}",
                rgba=rgba,
                texture=tex,
                specular=mat.specular,
                shininess=mat.shininess,
            )
        meshes = [b.mesh(f"{name}_{i}", p.mesh) for i, p in enumerate(geo.pieces)]
        bodies = []
        for k in range(slots):
            body_name = f"obj_{name}_{k}"
            body = ET.SubElement(
                b.worldbody, "body", name=body_name, mocap="true", pos=fmt((0, 0, -5 - k))
            )
            for i, p in enumerate(geo.pieces):
                b.visual_geom(
                    body,
                    name=f"{body_name}_{i}",
                    type="mesh",
                    mesh=meshes[i],
                    material=mats[p.material],
                )
            bodies.append(body_name)
        out[name] = tuple(bodies)
    return out


def build_cell(config: SimConfig, model: ArmModel = ASEA) -> CellModel:
    """The whole cell: arm, camera, world, catalogue slots and calibration boards."""
    lens = Lens(config.camera)
    b = MjcfBuilder("visioncell")
    b.option.attrib.update(timestep=f"{config.timestep_s:g}", integrator="implicitfast")
    ET.SubElement(b.root, "statistic", extent="2", center="0.4 0 0.5")
    ET.SubElement(
        b.visual,
        "global",
        offwidth=str(max(lens.ideal_width, 640)),
        offheight=str(max(lens.ideal_height, 480)),
    )
    ET.SubElement(
        b.visual, "quality", shadowsize=str(config.shadow_size), offsamples=str(config.offsamples)
    )
    ET.SubElement(b.visual, "map", znear="0.004", zfar="8")
    amb = config.layout.ambient
    ET.SubElement(b.visual, "headlight", ambient=fmt([amb] * 3), diffuse="0 0 0", specular="0 0 0")
    ET.SubElement(
        b.asset,
        "texture",
        name="sky",
        type="skybox",
        builtin="gradient",
        rgb1="0.8 0.82 0.84",
        rgb2="0.45 0.47 0.5",
        width="32",
        height="192",
    )
    flange = add_arm(b, model, config.dynamics, config.camera, lens)
    add_suction_cup(b, flange, config.gripper)
    cleats = add_world(b, config.layout)
    slots = _add_catalogue(b, config.slots_per_object, config.layout)
    boards = {spec.kind: add_board_body(b, spec, f"board_{spec.kind}") for spec in config.boards}
    return CellModel(b.to_xml(), b.assets, slots, tuple(cleats), boards)
