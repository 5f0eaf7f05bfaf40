"""The simulated cell in MuJoCo: torque-driven arm, eye-in-hand camera with a real lens,
conveyor, objects, calibration boards and lights (chapter sections 3.6.4 and 4.1).

Start with :class:`SimEngine` (one per process); :class:`SimDriver` and :class:`SimCamera`
put it behind the product's ``RobotDriver`` and ``Camera`` protocols.  Ground truth for
tests and benchmarks is ``engine.truth`` (:class:`~robot.sim.truth.SimTruth`), and for
sorting ``engine.bins()`` / ``engine.landings()`` (:mod:`robot.sim.gripper`,
:mod:`robot.sim.bins`).
"""

from robot.sim.bins import BinSpec, default_bins
from robot.sim.boards import BOARD_KINDS, BoardSpec, default_boards
from robot.sim.camera import DEFAULT_DIST, DEFAULT_T_EE_CAM, CameraSpec, Lens
from robot.sim.catalogue import CATALOGUE, CatalogueEntry, catalogue_names
from robot.sim.config import SimConfig
from robot.sim.controller import ControllerGains, JointController
from robot.sim.conveyor import SimConveyor
from robot.sim.demo import DEMO_OBJECTS, populate_demo
from robot.sim.driver import SimCamera, SimDriver
from robot.sim.engine import ArmSample, SimEngine, Snapshot
from robot.sim.gripper import Landing, SuctionCupSpec, suction_point
from robot.sim.mjcf import ArmDynamics, build_cell
from robot.sim.truth import BoardTruth, CameraTruth, ObjectTruth, SimTruth
from robot.sim.world import ConveyorSpec, ConveyorState, LightSpec, WorldLayout

__all__ = [
    "BOARD_KINDS",
    "CATALOGUE",
    "DEFAULT_DIST",
    "DEFAULT_T_EE_CAM",
    "DEMO_OBJECTS",
    "ArmDynamics",
    "ArmSample",
    "BinSpec",
    "BoardSpec",
    "BoardTruth",
    "CameraSpec",
    "CameraTruth",
    "CatalogueEntry",
    "ControllerGains",
    "ConveyorSpec",
    "ConveyorState",
    "JointController",
    "Landing",
    "Lens",
    "LightSpec",
    "ObjectTruth",
    "SimCamera",
    "SimConfig",
    "SimConveyor",
    "SimDriver",
    "SimEngine",
    "SimTruth",
    "Snapshot",
    "SuctionCupSpec",
    "WorldLayout",
    "build_cell",
    "catalogue_names",
    "default_bins",
    "default_boards",
    "populate_demo",
    "suction_point",
]
