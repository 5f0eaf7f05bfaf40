"""The simulation engine: MuJoCo model and data, the physics thread, the belt and the scene.

One :class:`SimEngine` per process plays the chapter's SimMechanics model (section 3.6.4)
and the experimental cell of section 4.1.  It owns

* the physics thread, which steps MuJoCo at ``config.timestep_s`` with the joint controller
  in the loop (torques in, angles and velocities out) and keeps simulated time in step
  with the wall clock times ``time_scale``;
* the conveyor and the objects riding it (kinematic mocap bodies: their poses are computed
  from the belt's state when a picture is taken), the calibration boards and the lights;
* lazily, the render thread (:class:`~robot.sim.render.RenderWorker`) with its own copy of
  the model, fed with :class:`Snapshot` objects.

Every public method is thread-safe (one lock guards the simulation state).  Without the
thread (:meth:`start` not called), :meth:`advance` steps the simulation synchronously,
which tests and benchmarks use for deterministic runs.
"""

from __future__ import annotations

import logging
import math
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass

import mujoco
import numpy as np
from numpy.typing import ArrayLike, NDArray

from robot.drivers.base import GripReport, MoveReport, check_grip_flag
from robot.errors import DriverError, SimError
from robot.kinematics import T_base_ee
from robot.model import ASEA, ArmModel, check_joints
from robot.sim.boards import BoardSpec
from robot.sim.builder import quat_from_matrix
from robot.sim.camera import Lens
from robot.sim.catalogue import CATALOGUE
from robot.sim.config import SimConfig
from robot.sim.controller import JointController
from robot.sim.gripper import Landing, payload_inertia, payload_mass_kg, ray_to_object
from robot.sim.mjcf import build_cell
from robot.sim.render import RenderWorker
from robot.sim.truth import BoardTruth, ObjectTruth, SimTruth
from robot.sim.world import BeltItem, Conveyor, ConveyorState, cleat_positions
from robot.trajectory import JointTrajectory
from vision.errors import InvalidInput

__all__ = ["ArmSample", "SimEngine", "Snapshot"]

log = logging.getLogger(__name__)

#: Largest |yaw| of a spawned object, radians (one turn either way).
MAX_ABS_YAW_RAD = 2.0 * math.pi
#: Largest |x|, |y|, |z| of a placed board, metres (the cell is a few metres across).
MAX_ABS_POSITION_M = 5.0


def _not_number(v: object) -> bool:
    """True unless ``v`` is a real number (booleans are not); NaN and infinity pass here
    and fail the range checks that follow."""
    return isinstance(v, bool | np.bool_) or not isinstance(
        v, int | float | np.integer | np.floating
    )


_CHUNK_STEPS = 20  # most steps per lock hold
_TICK_S = 0.002  # wall-clock period of the physics loop when it keeps up
_MAX_LAG_S = 0.1  # wall seconds of lag after which the loop stops trying to catch up
_SEAL_CHECK_STEPS = 5  # physics steps between checks for a part under the switched-on cup


@dataclass(frozen=True)
class ArmSample:
    """The arm at one instant of simulated time."""

    t_s: float
    stamp_s: float
    q: NDArray[np.float64]
    qd: NDArray[np.float64]
    moving: bool
    estopped: bool
    gripper_on: bool = False
    holding: bool = False


@dataclass(frozen=True)
class _Held:
    """The part on the suction cup: its id, catalogue name, slot and ``T_cup_obj``."""

    id: int
    name: str
    T_cup_obj: NDArray[np.float64]


@dataclass(frozen=True)
class Snapshot:
    """Everything the renderer needs to draw one instant (copied under the lock).

    ``stamp_s`` is ``time.monotonic()`` when it was taken: the exposure time of a frame.
    """

    t_s: float
    stamp_s: float
    q: NDArray[np.float64]
    qd: NDArray[np.float64]
    moving: bool
    estopped: bool
    mocap_pos: NDArray[np.float64]
    mocap_quat: NDArray[np.float64]
    geom_alpha: NDArray[np.float32]
    light_diffuse: NDArray[np.float32]
    light_specular: NDArray[np.float32]
    ambient: float
    gripper_on: bool = False
    holding: bool = False
    belt_travel_m: float = 0.0
    """The conveyor's encoder (its travel, metres) at this instant."""


def _quat_yaw(yaw: float) -> NDArray[np.float64]:
    return np.array([math.cos(yaw / 2.0), 0.0, 0.0, math.sin(yaw / 2.0)])


class SimEngine:
    """The simulated cell.

    Parameters
    ----------
    config : SimConfig, optional
        Model, camera, world and controller settings (default :class:`SimConfig()`).
    model : ArmModel
        The arm (link lengths, joint ranges, speed limits).
    q0 : array_like of shape (5,), optional
        Initial joints (default ``model.q_home``).
    time_scale : float
        Simulated seconds per wall-clock second for the physics thread.
    """

    # The part on the suction cup (set by ``_init_gripper``), declared here because
    # methods above ``_init_gripper`` assign it too.
    _held: _Held | None

    def __init__(
        self,
        config: SimConfig | None = None,
        *,
        model: ArmModel = ASEA,
        q0: ArrayLike | None = None,
        time_scale: float = 1.0,
    ) -> None:
        self.config = config or SimConfig()
        self.arm_model = model
        self.cell = build_cell(self.config, model)
        self.model = self.cell.compile()
        self.data = mujoco.MjData(self.model)
        if self.model.nq != 5 or self.model.nu != 5:
            raise AssertionError(
                f"the cell model must have 5 joints and 5 motors, got {self.model.nq}, {self.model.nu}"
            )
        self._lock = threading.RLock()
        self._rng = np.random.default_rng(self.config.seed)
        q = check_joints(model.q_home if q0 is None else q0, model)
        self.data.qpos[:] = q
        mujoco.mj_forward(self.model, self.data)
        self._M = np.zeros((5, 5))
        dyn = self.config.dynamics
        self.controller = JointController(
            self.config.timestep_s,
            dyn.torque_limit_n_m,
            model.max_acceleration_rad_s2,
            self.config.gains,
            q,
        )
        self.conveyor = Conveyor(self.config.layout.conveyor, at_end=self.config.belt_end)
        self._estopped = False
        self._time_scale = 1.0
        self.time_scale = time_scale
        self._init_scene()
        self.truth = SimTruth(self)
        self._listeners: list[Callable[[ArmSample], None]] = []
        self._thread: threading.Thread | None = None
        self._stop = threading.Event()
        self._users = 0
        self._renderer: RenderWorker | None = None
        self._renderer_lock = threading.Lock()
        self._next_id = 1
        self.steps = 0
        self._init_gripper()

    # -- scene book-keeping --------------------------------------------------------------
    def _body_mocap(self, name: str) -> int:
        bid = mujoco.mj_name2id(self.model, mujoco.mjtObj.mjOBJ_BODY, name)
        mid = int(self.model.body_mocapid[bid])
        if mid < 0:
            raise AssertionError(f"body {name!r} is not a mocap body")
        return mid

    def _body_geoms(self, name: str) -> NDArray[np.int64]:
        bid = mujoco.mj_name2id(self.model, mujoco.mjtObj.mjOBJ_BODY, name)
        return np.nonzero(self.model.geom_bodyid == bid)[0]

    def _init_scene(self) -> None:
        m = self.model
        self._mocap_pos = np.array([m.body_pos[b] for b in np.nonzero(m.body_mocapid >= 0)[0]])
        order = np.argsort(m.body_mocapid[m.body_mocapid >= 0])
        self._mocap_pos = self._mocap_pos[order]
        self._mocap_quat = np.tile([1.0, 0.0, 0.0, 0.0], (m.nmocap, 1))
        self._alpha = m.geom_rgba[:, 3].astype(np.float32).copy()
        self._slots: dict[str, list[tuple[int, NDArray[np.int64]]]] = {}
        self._free: dict[str, list[int]] = {}
        for name, bodies in self.cell.slot_bodies.items():
            self._slots[name] = [(self._body_mocap(b), self._body_geoms(b)) for b in bodies]
            self._free[name] = list(range(len(bodies)))
            for _, geoms in self._slots[name]:
                self._alpha[geoms] = 0.0
        self._item_slot: dict[int, tuple[str, int]] = {}
        self._cleats = np.array(
            [self._body_mocap(b) for b in self.cell.cleat_bodies], dtype=np.int64
        )
        self._boards: dict[str, tuple[BoardSpec, int, NDArray[np.int64]]] = {}
        self._board_pose: dict[str, NDArray[np.float64]] = {}
        for spec in self.config.boards:
            body = self.cell.board_bodies[spec.kind]
            geoms = self._body_geoms(body)
            self._boards[spec.kind] = (spec, self._body_mocap(body), geoms)
            self._alpha[geoms] = 0.0
        self._light_ids = {
            spec.name: mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_LIGHT, spec.name)
            for spec in self.config.layout.lights
        }
        self._light_base = m.light_diffuse.astype(np.float32).copy()
        self._light_base_spec = m.light_specular.astype(np.float32).copy()
        self._intensity = {name: 1.0 for name in self.config.layout.light_names}

    # -- life cycle ----------------------------------------------------------------------
    @property
    def running(self) -> bool:
        """True while the physics thread runs."""
        return self._thread is not None and self._thread.is_alive()

    def start(self) -> None:
        """Start the physics thread (idempotent)."""
        with self._lock:
            if self.running:
                return
            self._stop.clear()
            self._thread = threading.Thread(target=self._run, name="sim-physics", daemon=True)
            self._thread.start()

    def stop(self, timeout_s: float = 2.0) -> None:
        """Stop the physics and render threads (idempotent; returns within ``timeout_s``)."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout_s)
            self._thread = None
        with self._renderer_lock:
            if self._renderer is not None:
                self._renderer.close(timeout_s)
                self._renderer = None

    def acquire(self) -> None:
        """Register a user (driver or camera); the first one starts the engine."""
        with self._lock:
            self._users += 1
            if self._users == 1:
                self.start()

    def release(self) -> None:
        """Unregister a user; the last one stops the engine."""
        with self._lock:
            self._users = max(0, self._users - 1)
            last = self._users == 0
        if last:
            self.stop()

    @property
    def time_scale(self) -> float:
        """Simulated seconds per wall-clock second."""
        return self._time_scale

    @time_scale.setter
    def time_scale(self, value: float) -> None:
        if not (value > 0 and math.isfinite(value)) or value > 1000:
            raise ValueError(f"time_scale must be in (0, 1000], got {value!r}")
        with self._lock:
            self._time_scale = float(value)
            self._rebase = True

    def add_listener(self, fn: Callable[[ArmSample], None]) -> None:
        """Call ``fn(sample)`` from the physics thread at ``config.state_rate_hz``."""
        with self._lock:
            self._listeners.append(fn)

    def remove_listener(self, fn: Callable[[ArmSample], None]) -> None:
        """Stop calling ``fn``."""
        with self._lock:
            if fn in self._listeners:
                self._listeners.remove(fn)

    # -- physics -------------------------------------------------------------------------
    def _step(self) -> None:
        m, d = self.model, self.data
        mujoco.mj_step1(m, d)
        mujoco.mj_fullM(m, d, self._M)
        d.ctrl[:] = self.controller.torque(
            d.time, d.qpos.copy(), d.qvel.copy(), self._M, d.qfrc_bias
        )
        mujoco.mj_step2(m, d)
        self.steps += 1

    def _advance_locked(self, n: int) -> None:
        for _ in range(n):
            self._step()
            if self._suction and self._held is None and self.steps % _SEAL_CHECK_STEPS == 0:
                self._try_seal_locked()
        removed = self.conveyor.advance(n * self.config.timestep_s)
        for obj_id in removed:
            self._free_slot(obj_id)

    def advance(self, seconds: float) -> None:
        """Step the simulation by ``seconds`` of simulated time, synchronously.

        Only without the physics thread (tests, benchmarks); raises ``RuntimeError`` while
        it runs.
        """
        if self.running:
            raise RuntimeError("advance() is for a stopped engine; the physics thread is running")
        n = round(seconds / self.config.timestep_s)
        with self._lock:
            while n > 0:
                k = min(n, 200)
                self._advance_locked(k)
                n -= k

    def _run(self) -> None:
        dt = self.config.timestep_s
        pub_period = 1.0 / self.config.state_rate_hz
        next_pub = 0.0
        wall0 = time.monotonic()
        sim0 = self.data.time
        self._rebase = False
        try:
            while not self._stop.is_set():
                now = time.monotonic()
                with self._lock:
                    if self._rebase:
                        wall0, sim0, self._rebase = now, self.data.time, False
                    behind = sim0 + (now - wall0) * self._time_scale - self.data.time
                    if behind > _MAX_LAG_S * self._time_scale:
                        wall0, sim0 = now, self.data.time  # cannot keep up: run flat out
                        behind = _CHUNK_STEPS * dt
                    n = min(_CHUNK_STEPS, int(behind / dt))
                    if n > 0:
                        self._advance_locked(n)
                    if now >= next_pub:
                        next_pub = now + pub_period
                        sample = self._sample_locked()
                        listeners = list(self._listeners)
                    else:
                        listeners = []
                for fn in listeners:
                    fn(sample)
                if n < _CHUNK_STEPS:
                    self._stop.wait(_TICK_S)
                else:
                    time.sleep(0)  # let other threads take the lock
        except Exception:  # pragma: no cover - a bug; keep the process alive and say so
            log.exception("simulation thread failed")
            raise

    # -- the arm -------------------------------------------------------------------------
    def _sample_locked(self) -> ArmSample:
        d = self.data
        return ArmSample(
            float(d.time),
            time.monotonic(),
            d.qpos.copy(),
            d.qvel.copy(),
            self.controller.moving,
            self._estopped,
            self._suction,
            self._held is not None,
        )

    def arm_state(self) -> ArmSample:
        """The arm now."""
        with self._lock:
            return self._sample_locked()

    @property
    def estopped(self) -> bool:
        """True between :meth:`brake` and :meth:`clear_estop`."""
        return self._estopped

    def start_move(self, traj: JointTrajectory, on_done: Callable[[MoveReport], None]) -> None:
        """Track ``traj`` from now; ``on_done(report)`` runs on the physics thread at the end.

        Raises :class:`~robot.errors.DriverError` if a move is still executing or stopping.
        """
        with self._lock:
            if self._estopped:
                raise DriverError("emergency stop is active")
            if self.controller.moving:
                raise DriverError("the previous move is still executing or stopping")
            self.controller.start(traj, self.data.time, on_done)

    def stop_motion(self, reason: str = "stopped") -> None:
        """Decelerate the current move to rest (it then reports ``reason``)."""
        with self._lock:
            if self.controller.moving:
                self.controller.stop(self.data.time, reason)

    def brake(self) -> None:
        """Emergency stop: hold the measured position at once; latched until :meth:`clear_estop`."""
        with self._lock:
            self._estopped = True
            self.controller.brake(self.data.time, self.data.qpos.copy())

    def clear_estop(self) -> None:
        """Release the emergency-stop latch (the arm keeps holding where it is)."""
        with self._lock:
            self._estopped = False

    def set_joints(self, q: ArrayLike) -> None:
        """Put the arm at ``q`` at rest, at once (tests and set-up; not a motion command)."""
        qa = check_joints(np.asarray(q, dtype=np.float64).reshape(5), self.arm_model)
        with self._lock:
            if self.controller.moving:
                raise DriverError("cannot set the joints during a move")
            self.data.qpos[:] = qa
            self.data.qvel[:] = 0.0
            mujoco.mj_forward(self.model, self.data)
            self.controller.hold(self.data.time, qa)

    # -- objects on the belt -------------------------------------------------------------
    def spawn(
        self,
        name: str,
        *,
        s_m: float = 0.0,
        lateral_m: float = 0.0,
        yaw_rad: float | None = None,
    ) -> ObjectTruth:
        """Put a catalogue object on the belt ``s_m`` from its entry; returns its true pose.

        ``yaw_rad`` defaults to a seeded random angle.  Every value is checked before the
        world changes (:class:`~vision.errors.InvalidInput`, a ``ValueError``, quoting it).
        """
        if name not in CATALOGUE:
            raise InvalidInput(
                f"unknown catalogue name {name!r}; valid names: {', '.join(CATALOGUE)}"
            )
        spec = self.config.layout.conveyor
        if _not_number(s_m) or not (0.0 <= s_m <= spec.length_m):
            raise InvalidInput(
                f"position along the belt must be in [0, {spec.length_m:g}] m, got {s_m!r}"
            )
        half = spec.width_m / 2.0
        if _not_number(lateral_m) or not (abs(lateral_m) <= half):
            raise InvalidInput(f"lateral offset must be within +-{half:g} m, got {lateral_m!r}")
        if yaw_rad is not None and (_not_number(yaw_rad) or not (abs(yaw_rad) <= MAX_ABS_YAW_RAD)):
            raise InvalidInput(
                f"yaw_rad must be a finite angle within +-{MAX_ABS_YAW_RAD:.6g} rad (one turn), "
                f"got {yaw_rad!r}"
            )
        with self._lock:
            if not self._free[name]:
                raise SimError(
                    f"all {len(self._slots[name])} slots for {name!r} are in use; remove one first"
                )
            yaw = float(self._rng.uniform(-math.pi, math.pi)) if yaw_rad is None else float(yaw_rad)
            slot = self._free[name].pop(0)
            obj_id = self._next_id
            self._next_id += 1
            self.conveyor.items[obj_id] = BeltItem(obj_id, name, float(s_m), float(lateral_m), yaw)
            self._item_slot[obj_id] = (name, slot)
            self._alpha[self._slots[name][slot][1]] = 1.0
            return self._truth_locked(obj_id)

    def _free_slot(self, obj_id: int) -> None:
        name, slot = self._item_slot.pop(obj_id)
        self._free[name].append(slot)
        self._free[name].sort()
        self._alpha[self._slots[name][slot][1]] = 0.0

    def remove(self, obj_id: int) -> None:
        """Take an object off the belt (:class:`~robot.errors.SimError` if there is none)."""
        with self._lock:
            if obj_id not in self.conveyor.items:
                raise SimError(f"no object with id {obj_id} on the belt")
            del self.conveyor.items[obj_id]
            self._free_slot(obj_id)

    def clear_objects(self) -> None:
        """Remove every object (a part on the cup too; the bins' records stay)."""
        with self._lock:
            for obj_id in list(self.conveyor.items):
                self.remove(obj_id)
            if self._held is not None:
                held, self._held = self._held, None
                self._set_payload_locked(None)
                self._free_slot(held.id)

    def _truth_locked(self, obj_id: int) -> ObjectTruth:
        it = self.conveyor.items[obj_id]
        T = self.config.layout.conveyor.T_base_item(it.s_m, it.lateral_m, it.yaw_rad)
        T.setflags(write=False)
        return ObjectTruth(
            it.id, it.name, T, it.s_m, it.lateral_m, it.yaw_rad, CATALOGUE[it.name].trainable
        )

    def objects(self) -> list[ObjectTruth]:
        """Every object on the belt with its true pose, by id."""
        with self._lock:
            return [self._truth_locked(i) for i in sorted(self.conveyor.items)]

    def object_geoms(self, obj_id: int) -> NDArray[np.int64]:
        """Model geom ids of an object on the belt (for segmentation renders)."""
        with self._lock:
            if obj_id not in self._item_slot:
                raise SimError(f"no object with id {obj_id} on the belt")
            name, slot = self._item_slot[obj_id]
            return self._slots[name][slot][1].copy()

    def configure_conveyor(
        self,
        *,
        running: bool | None = None,
        speed_m_s: float | None = None,
        mode: str | None = None,
        dwell_s: float | str | None = "keep",
    ) -> ConveyorState:
        """Start/stop the belt, set its speed, mode and dwell (see :class:`~robot.sim.world.Conveyor`)."""
        with self._lock:
            return self.conveyor.configure(
                running=running, speed_m_s=speed_m_s, mode=mode, dwell_s=dwell_s
            )

    def halt_conveyor(self) -> None:
        """Emergency stop of the belt (latched until :meth:`resume_conveyor`)."""
        with self._lock:
            self.conveyor.halt()

    def resume_conveyor(self) -> None:
        """Release the emergency stop of the belt (it runs again if it was running)."""
        with self._lock:
            self.conveyor.resume()

    def release_conveyor(self) -> None:
        """Index mode: let the item at the station go on."""
        with self._lock:
            self.conveyor.release()

    @property
    def conveyor_state(self) -> ConveyorState:
        """Belt settings and whether it holds an item at the station."""
        with self._lock:
            return self.conveyor.state

    # -- boards and lights ---------------------------------------------------------------
    @property
    def board_kinds(self) -> tuple[str, ...]:
        """Kinds of board this cell can place."""
        return tuple(self._boards)

    def place_board(self, kind: str, T_base_board: ArrayLike) -> BoardTruth:
        """Show the board of ``kind`` at ``T_base_board`` (4x4, see :mod:`robot.sim.boards`)."""
        if kind not in self._boards:
            raise SimError(f"no {kind!r} board in this cell; boards: {', '.join(self._boards)}")
        try:
            T = np.asarray(T_base_board, dtype=np.float64)
        except (TypeError, ValueError):
            raise InvalidInput(f"T_base_board must be a 4x4 matrix, got {T_base_board!r}") from None
        if T.shape != (4, 4) or not np.all(np.isfinite(T)):
            raise InvalidInput(f"T_base_board must be a finite 4x4 matrix, got shape {T.shape}")
        R = T[:3, :3]
        if (
            not np.allclose(R @ R.T, np.eye(3), atol=1e-6)
            or np.linalg.det(R) < 0
            or not np.allclose(T[3], [0, 0, 0, 1])
        ):
            raise InvalidInput(f"T_base_board must be a rigid transform, got {T.tolist()}")
        if not np.all(np.abs(T[:3, 3]) <= MAX_ABS_POSITION_M):
            raise InvalidInput(
                f"T_base_board must place the board within {MAX_ABS_POSITION_M:g} m of the base "
                f"on each axis, got position {T[:3, 3].tolist()}"
            )
        T = T.copy()
        T.setflags(write=False)
        with self._lock:
            spec, _, geoms = self._boards[kind]
            self._board_pose[kind] = T
            self._alpha[geoms] = 1.0
            return BoardTruth(spec, T)

    def remove_board(self, kind: str) -> None:
        """Hide the board of ``kind`` (no-op if it is not placed)."""
        if kind not in self._boards:
            raise SimError(f"no {kind!r} board in this cell; boards: {', '.join(self._boards)}")
        with self._lock:
            self._board_pose.pop(kind, None)
            self._alpha[self._boards[kind][2]] = 0.0

    def boards(self) -> list[BoardTruth]:
        """Placed boards with their true poses."""
        with self._lock:
            return [BoardTruth(self._boards[k][0], T) for k, T in self._board_pose.items()]

    def set_light(self, name: str, intensity: float) -> None:
        """Scale light ``name`` (or the ``"ambient"`` headlight) to ``intensity`` times its default."""
        if name not in self._intensity:
            raise InvalidInput(f"unknown light {name!r}; lights: {', '.join(self._intensity)}")
        if _not_number(intensity) or not (0.0 <= intensity <= 5.0):
            raise InvalidInput(f"intensity must be in [0, 5], got {intensity!r}")
        with self._lock:
            self._intensity[name] = float(intensity)

    def lights(self) -> dict[str, float]:
        """Intensity factor of every light."""
        with self._lock:
            return dict(self._intensity)

    # -- snapshots and rendering ---------------------------------------------------------
    def snapshot(self) -> Snapshot:
        """Copy what the renderer needs, now (cheap: a few small arrays)."""
        with self._lock:
            d = self.data
            pos = self._mocap_pos.copy()
            quat = self._mocap_quat.copy()
            spec = self.config.layout.conveyor
            pos[self._cleats] = cleat_positions(spec, self.conveyor.travel_m, len(self._cleats))
            for obj_id, it in self.conveyor.items.items():
                name, slot = self._item_slot[obj_id]
                mid = self._slots[name][slot][0]
                T = spec.T_base_item(it.s_m, it.lateral_m, it.yaw_rad)
                pos[mid] = T[:3, 3]
                quat[mid] = _quat_yaw(it.yaw_rad)
            if self._held is not None:
                name, slot = self._item_slot[self._held.id]
                mid = self._slots[name][slot][0]
                T = self._T_base_cup_locked() @ self._held.T_cup_obj
                pos[mid] = T[:3, 3]
                quat[mid] = quat_from_matrix(T[:3, :3])
            for kind, T in self._board_pose.items():
                mid = self._boards[kind][1]
                pos[mid] = T[:3, 3]
                quat[mid] = quat_from_matrix(T[:3, :3])
            diffuse = self._light_base.copy()
            specular = self._light_base_spec.copy()
            for name, lid in self._light_ids.items():
                diffuse[lid] *= self._intensity[name]
                specular[lid] *= self._intensity[name]
            ambient = self.config.layout.ambient * self._intensity["ambient"]
            return Snapshot(
                float(d.time),
                time.monotonic(),
                d.qpos.copy(),
                d.qvel.copy(),
                self.controller.moving,
                self._estopped,
                pos,
                quat,
                self._alpha.copy(),
                diffuse,
                specular,
                ambient,
                self._suction,
                self._held is not None,
                float(self.conveyor.travel_m),
            )

    def renderer(self) -> RenderWorker:
        """The render thread (started on first use, at the ideal canvas size of the lens)."""
        with self._renderer_lock:
            if self._renderer is None:
                lens = Lens(self.config.camera)
                self._renderer = RenderWorker(
                    self.model, lens.ideal_width, lens.ideal_height, "eye"
                )
            return self._renderer

    @staticmethod
    def apply_snapshot(model: mujoco.MjModel, data: mujoco.MjData, snap: Snapshot) -> None:
        """Load ``snap`` into a render-side model copy and data, and compute poses."""
        data.qpos[:] = snap.q
        data.qvel[:] = snap.qd
        data.mocap_pos[:] = snap.mocap_pos
        data.mocap_quat[:] = snap.mocap_quat
        model.geom_rgba[:, 3] = snap.geom_alpha
        model.light_diffuse[:] = snap.light_diffuse
        model.light_specular[:] = snap.light_specular
        model.vis.headlight.ambient[:] = snap.ambient
        mujoco.mj_kinematics(model, data)
        mujoco.mj_camlight(model, data)

    # -- suction gripper and bins --------------------------------------------------------
    def _init_gripper(self) -> None:
        self._cup = self.config.gripper
        self._payload_body = mujoco.mj_name2id(self.model, mujoco.mjtObj.mjOBJ_BODY, "payload")
        m = self.model
        self._payload_empty = (
            float(m.body_mass[self._payload_body]),
            m.body_inertia[self._payload_body].copy(),
        )
        self._suction = False
        self._held = None
        self._landings: list[Landing] = []

    def _T_base_cup_locked(self) -> NDArray[np.float64]:
        return T_base_ee(self.data.qpos, self.arm_model) @ self._cup.T_ee_cup

    def _set_payload_locked(self, held: _Held | None) -> None:
        """Load the payload body with ``held``'s mass and inertia (None: empty again)."""
        m, b = self.model, self._payload_body
        if held is None:
            m.body_mass[b], m.body_inertia[b] = self._payload_empty[0], self._payload_empty[1]
            m.body_ipos[b] = 0.0
            m.body_iquat[b] = (1.0, 0.0, 0.0, 0.0)
        else:
            com_obj, inertia = payload_inertia(held.name)
            m.body_mass[b] = payload_mass_kg(held.name)
            m.body_inertia[b] = inertia
            m.body_ipos[b] = held.T_cup_obj[:3, :3] @ com_obj + held.T_cup_obj[:3, 3]
            m.body_iquat[b] = quat_from_matrix(held.T_cup_obj[:3, :3])
        # Subtree masses and the other constants derived from the masses.
        mujoco.mj_setConst(m, mujoco.MjData(m))

    def _try_seal_locked(self) -> bool:
        """Seal on the belt object under the cup, if one is within reach of the lip."""
        cup = self._cup
        T_cup = self._T_base_cup_locked()
        lip, axis = T_cup[:3, 3], T_cup[:3, 2]
        spec = self.config.layout.conveyor
        cos_tilt = math.cos(math.radians(cup.max_tilt_deg))
        for obj_id in sorted(self.conveyor.items):
            it = self.conveyor.items[obj_id]
            b = CATALOGUE[it.name].geometry().bounds
            T_obj = spec.T_base_item(it.s_m, it.lateral_m, it.yaw_rad)
            rel = lip - T_obj[:3, 3]
            reach = float(np.abs(b).max()) * math.sqrt(2.0) + cup.radius_m
            if math.hypot(rel[0], rel[1]) > reach or not (
                -cup.max_press_m <= rel[2] <= b[1, 2] + cup.seal_gap_m + 0.01
            ):
                continue
            T_obj_cup = np.linalg.inv(T_obj) @ T_cup
            hit = ray_to_object(it.name, T_obj_cup, max_back_m=cup.max_press_m)
            if hit is None:
                continue
            dist, normal = hit
            if not (-cup.max_press_m <= dist <= cup.seal_gap_m):
                continue
            if float(-(T_obj_cup[:3, 2] @ normal)) < cos_tilt:
                continue
            if payload_mass_kg(it.name) > cup.max_payload_kg:
                continue
            # Suction pulls a part that is a little short of the lip up against it.
            T_seal = T_obj.copy()
            T_seal[:3, 3] -= max(dist, 0.0) * axis
            held = _Held(obj_id, it.name, np.linalg.inv(T_cup) @ T_seal)
            del self.conveyor.items[obj_id]
            self._held = held
            self._set_payload_locked(held)
            return True
        return False

    def _release_locked(self) -> Landing:
        held = self._held
        assert held is not None
        T = self._T_base_cup_locked() @ held.T_cup_obj
        self._held = None
        self._set_payload_locked(None)
        spec = self.config.layout.conveyor
        x, y = float(T[0, 3]), float(T[1, 3])
        place = "floor"
        for b in self.config.layout.bins:
            if b.contains((x, y)):
                place = b.name
                break
        else:
            on_belt = (
                abs(x - spec.centre_x_m) <= spec.width_m / 2.0
                and spec.start_y_m <= y <= spec.end_y_m
                and T[2, 3] >= spec.surface_z_m - 0.01
            )
            if on_belt:
                place = "belt"
        landing = Landing(held.id, held.name, place, T[:3, 3].copy(), float(self.data.time))
        self._landings.append(landing)
        if place == "belt":
            yaw = math.atan2(T[1, 0], T[0, 0])
            self.conveyor.items[held.id] = BeltItem(
                held.id, held.name, y - spec.start_y_m, x - spec.centre_x_m, yaw
            )
        else:
            self._free_slot(held.id)
        return landing

    def grip(self, on: bool) -> GripReport:
        """Switch the suction on (seal on the part under the cup now, or on contact later)
        or off (release the part: it drops into the bin, onto the belt or the floor below).

        Raises :class:`~robot.errors.DriverError` during an emergency stop.
        """
        on = check_grip_flag(on)
        with self._lock:
            if self._estopped:
                raise DriverError("emergency stop is active: the gripper keeps its state")
            if on:
                self._suction = True
                if self._held is None and not self._try_seal_locked():
                    return GripReport(True, False, detail="suction on; no part under the cup")
                assert self._held is not None
                return GripReport(True, True, part_id=self._held.id, detail="part held")
            self._suction = False
            if self._held is None:
                return GripReport(False, False, detail="suction off; nothing was held")
            landing = self._release_locked()
            return GripReport(
                False, False, released_id=landing.id, detail=f"released over {landing.place}"
            )

    @property
    def gripper_on(self) -> bool:
        """True while the suction is on."""
        return self._suction

    def held_object(self) -> tuple[int, str, NDArray[np.float64]] | None:
        """The part on the cup now: ``(id, catalogue name, T_base_obj)``, or None (truth)."""
        with self._lock:
            if self._held is None:
                return None
            T = self._T_base_cup_locked() @ self._held.T_cup_obj
            return self._held.id, self._held.name, T

    def bins(self) -> dict[str, tuple[int, ...]]:
        """Ids of the objects that landed in each bin, every bin listed (truth)."""
        with self._lock:
            out: dict[str, tuple[int, ...]] = {b.name: () for b in self.config.layout.bins}
            for landing in self._landings:
                if landing.place in out:
                    out[landing.place] = (*out[landing.place], landing.id)
            return out

    def landings(self) -> list[Landing]:
        """Every release so far, in order (truth: bins, the belt or the floor)."""
        with self._lock:
            return list(self._landings)
