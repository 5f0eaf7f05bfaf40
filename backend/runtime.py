"""The one assembly of a running cell: settings -> database, cell row, hardware, cell, view.

:class:`CellRuntime` is an async context manager used by the FastAPI lifespan
(:func:`backend.app.create_app`), ``visioncell serve`` and the CLI's in-process runs, and by
the benchmarks; nothing else wires these parts together::

    async with CellRuntime(settings) as rt:
        job = rt.cell.home()
        await rt.jobs.wait(job)

Entering builds, in this order, and exiting undoes in the reverse order:

1. the database engine, checked to be at the newest Alembic revision
   (:class:`StartupError` says to run ``visioncell db upgrade`` otherwise);
2. the cell's row, named by ``Settings.cell_name`` (created on first start), whose id
   every per-cell service (calibration sessions, active calibrations, inspections) is given;
3. the hardware the settings name: robot driver, camera, the cell's world (conveyor,
   layout of station, belt and bins, and in the simulator its truth) and, when either is
   simulated, the MuJoCo engine behind both (with its belt as a conveyor under the E-STOP
   and its table and belt as the collision model);
4. the :class:`~backend.cell.Cell` (driver connected, camera feed, jobs, event bus);
5. the viser 3D view, when ``view3d_enabled`` (or ``view3d=True``).

The database checks of steps 1 and 2 are :mod:`backend.startup`, steps 3 to 5
:mod:`backend.assembly`; this module puts them and the cell's services together.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
from typing import TYPE_CHECKING, Any

from backend.assembly import assemble_cell, start_view3d
from backend.auth import load_known_tokens
from backend.caches import AuthCache
from backend.cell import Cell, EventBus
from backend.db.session import Database
from backend.estoplog import EStopLog
from backend.hardware import CellWorld, Hardware, NominalCamera
from backend.heavy import HeavyPool
from backend.inspection import recovery
from backend.inspection.state import InspectionState
from backend.jobs import JobManager
from backend.knowntokens import KnownTokens
from backend.planning import BackgroundStore
from backend.readcache import ReadCache
from backend.recognition.index import LiveIndex, load_live_index
from backend.settings import Settings
from backend.startup import StartupError, check_database, ensure_cell_row
from backend.taskutil import cancel_and_wait
from backend.throttle import SignInThrottle

if TYPE_CHECKING:
    from backend.authsync import AuthSync
    from backend.plc.links import PlcLinks
    from backend.recognition.autothreshold import ThresholdKeeper
    from backend.recognition.sync import IndexSync
    from backend.view3d import View3D
    from robot.cellworld import CellLayout, TruthSource
    from robot.drivers.conveyor import Conveyor
    from robot.sim import SimEngine

__all__ = ["CellRuntime", "StartupError", "check_database", "ensure_cell_row"]

log = logging.getLogger(__name__)


async def _cancel(task: asyncio.Task[None]) -> None:
    await cancel_and_wait(task)


class CellRuntime:
    """The running system of one cell (see the module docstring).

    Parameters
    ----------
    settings : Settings
        The process's configuration.
    view3d : bool, optional
        Start the 3D view (default: ``settings.view3d_enabled``).
    hardware : Hardware, optional
        Driver, camera and engine built by the caller (the fault campaign puts the serial
        driver in front of a simulated arm); default:
        :func:`~backend.hardware.make_hardware` of the settings.

    Attributes (after entering)
    ---------------------------
    settings : Settings
    database : Database
    cell_id : int
        Id of the cell's row (``settings.cell_name``).
    cell : Cell
    bus : EventBus
    conveyor : Conveyor
        The cell's conveyor (the simulator's belt, or a fixed station).
    layout : CellLayout
        Station, belt and bins (the simulator's, or the layout file's).
    truth : TruthSource or None
        Where the objects truly are (simulator only; read by evaluations, never decisions).
    nominal_camera : NominalCamera or None
        The camera model and mounting used without an active calibration, when exact.
    sim : SimEngine or None
        The simulated cell, when the driver or the camera is simulated (its own routes,
        its calibration run, the 3D view's scene and the benchmarks).
    view3d : View3D or None
    inspection : InspectionState
        The belt background and the continuous run of the inspection service.
    """

    def __init__(
        self, settings: Settings, *, view3d: bool | None = None, hardware: Hardware | None = None
    ) -> None:
        self.settings = settings
        self._hardware = hardware
        self._want_view = settings.view3d_enabled if view3d is None else bool(view3d)
        self.bus = EventBus()
        self._database: Database | None = None
        self._cell: Cell | None = None
        self._cell_id: int | None = None
        self._sim: SimEngine | None = None
        self._world: CellWorld | None = None
        self.view3d: View3D | None = None
        self._live_index: LiveIndex | None = None
        #: Keeps the live index in step with other processes' changes (after entering).
        self.index_sync: IndexSync | None = None
        #: Empty-belt backgrounds grabbed by teaches, for later teaches of this cell.
        self.teach_backgrounds = BackgroundStore()
        #: Ids of the failed rows written at start-up for inspections left unfinished.
        self.interrupted_at_start: list[int] = []
        #: The inspection service's belt background and continuous run.
        self.inspection = InspectionState()
        #: Failed sign-ins per client address (REST, WebSocket and the 3D view share it).
        #: Tokens seen valid in the last hour: the emergency stop's sign-in, from memory
        #: (``backend.knowntokens``); every successful sign-in of the cache feeds it.
        self.known_tokens = KnownTokens()
        #: Successful sign-ins reused for 2 s (``backend.caches``).
        self.auth_cache = AuthCache(known=self.known_tokens)
        #: Writes every E-STOP press and reset to the audit trail (after entering).
        self.estop_log: EStopLog | None = None
        #: Hot list and status reads reused for ``read_cache_ttl_s`` (``backend.readcache``).
        self.read_cache = ReadCache(ttl_s=settings.read_cache_ttl_s)
        #: On PostgreSQL: drops the sign-ins other processes revoke (``backend.authsync``).
        self.auth_sync: AuthSync | None = None
        #: The PLC links while the app's lifespan runs them (``backend.plc.links``).
        self.plc_links: PlcLinks | None = None
        self.signin_throttle = SignInThrottle(
            max_failures=settings.signin_max_failures,
            window_s=settings.signin_window_s,
            block_s=settings.signin_block_s,
            max_clients=settings.signin_max_clients,
        )
        #: Threads and job slots of the requests' heavy work: decoding uploads, features,
        #: report plots (``backend.heavy``).
        #: A fresh pool each time the runtime is entered; closed at exit.
        self.heavy = self._new_heavy_pool()
        #: Recomputes the automatic threshold after changes (after entering, when
        #: ``threshold_follow``; ``backend.recognition.autothreshold``).
        self.threshold_keeper: ThresholdKeeper | None = None
        self._stack: contextlib.AsyncExitStack | None = None

    def _new_heavy_pool(self) -> HeavyPool:
        s = self.settings
        return HeavyPool(
            workers=s.heavy_workers,
            max_jobs=s.heavy_jobs,
            admit_wait_s=s.heavy_admit_wait_s,
            max_pixels=s.max_request_pixels,
            max_analysed_pixels=s.max_analysed_pixels,
        )

    # -- accessors (raise a clear error before start) -----------------------------------------
    @property
    def database(self) -> Database:
        """The database (after entering)."""
        if self._database is None:
            raise RuntimeError("the cell runtime is not running")
        return self._database

    @property
    def cell(self) -> Cell:
        """The cell (after entering)."""
        if self._cell is None:
            raise RuntimeError("the cell runtime is not running")
        return self._cell

    @property
    def live_index(self) -> LiveIndex:
        """The index of every trained view, built from the database at start (after entering)."""
        if self._live_index is None:
            raise RuntimeError("the cell runtime is not running")
        return self._live_index

    @property
    def cell_id(self) -> int:
        """Id of the cell's row (after entering)."""
        if self._cell_id is None:
            raise RuntimeError("the cell runtime is not running")
        return self._cell_id

    @property
    def world(self) -> CellWorld:
        """The cell's conveyor, layout and truth (after entering)."""
        if self._world is None:
            raise RuntimeError("the cell runtime is not running")
        return self._world

    @property
    def conveyor(self) -> Conveyor:
        """The cell's conveyor (after entering)."""
        return self.world.conveyor

    @property
    def layout(self) -> CellLayout:
        """Station, belt and bins (after entering)."""
        return self.world.layout

    @property
    def truth(self) -> TruthSource | None:
        """Where the objects truly are: the simulator only; for evaluations."""
        return None if self._world is None else self._world.truth

    @property
    def nominal_camera(self) -> NominalCamera | None:
        """Camera model and mounting without an active calibration, when exact (simulator)."""
        return None if self._world is None else self._world.nominal

    @property
    def sim(self) -> SimEngine | None:
        """The simulated cell (None on a real cell, and before entering)."""
        return self._sim

    @property
    def jobs(self) -> JobManager:
        """The cell's jobs."""
        return self.cell.jobs

    @property
    def running(self) -> bool:
        """Whether the runtime has been entered and not exited."""
        return self._cell is not None

    @property
    def cell_name(self) -> str:
        """``settings.cell_name``."""
        return self.settings.cell_name

    # -- life cycle ----------------------------------------------------------------------
    async def __aenter__(self) -> CellRuntime:
        if self._stack is not None:
            raise RuntimeError("a CellRuntime can be entered once at a time")
        stack = contextlib.AsyncExitStack()
        await stack.__aenter__()
        self._stack = stack
        try:
            await self._build(stack)
        except BaseException:
            self._stack = None
            await stack.aclose()
            self._clear()
            raise
        return self

    async def __aexit__(self, *exc: Any) -> None:
        stack, self._stack = self._stack, None
        try:
            if stack is not None:
                await stack.aclose()
        finally:
            self._clear()

    def _clear(self) -> None:
        self.threshold_keeper = None
        self._cell = None
        self._database = None
        self._live_index = None
        self.view3d = None
        self._sim = None
        self._world = None

    async def _build(self, stack: contextlib.AsyncExitStack) -> None:
        s = self.settings
        db = Database(s.database_url, busy_timeout_s=s.database_busy_timeout_s)
        stack.push_async_callback(db.dispose)
        self.heavy = self._new_heavy_pool()
        stack.callback(self.heavy.close)
        # What the services write drops what the caches read of it (``backend.caches``);
        # a runtime entered again starts with empty caches.
        db.on_change += [self.read_cache.on_change, self.auth_cache.on_change]
        stack.callback(self.read_cache.clear)
        stack.callback(self.auth_cache.clear)
        await check_database(db)
        self._database = db
        self._cell_id = await ensure_cell_row(db, s.cell_name)
        async with db.session() as session:  # the emergency stop knows every live token
            await load_known_tokens(session, self.known_tokens)
        # Every E-STOP press and reset goes to the audit trail after the stop itself.
        self.estop_log = EStopLog(db, s.cell_name)
        self.estop_log.start(self.bus)
        stack.push_async_callback(self.estop_log.stop)
        self._live_index = await load_live_index(db, s)
        from backend.recognition.sync import IndexSync

        self.index_sync = IndexSync(
            db, self._live_index, poll_s=s.index_poll_s, listen=s.index_listen
        )
        self.index_sync.start()
        stack.push_async_callback(self.index_sync.stop)
        if s.auth_listen and db.url.startswith("postgresql"):
            from backend.authsync import AuthSync

            self.auth_sync = AuthSync(db.url, self.auth_cache)
            self.auth_sync.start()
            stack.push_async_callback(self.auth_sync.stop)
        # Inspections a previous process left unfinished (killed mid-inspection) become
        # complete failed rows before this one inspects; the stored backgrounds come back.
        owners: dict[int, str] = {}
        self.interrupted_at_start = await recovery.mark_interrupted(db, self.cell_id, owners=owners)
        from backend.jobjournal import interrupted_jobs

        interrupted = await interrupted_jobs(db, self.cell_id, inspections=owners)
        self.teach_backgrounds.images.update(await recovery.load_backgrounds(db, self.cell_id))
        self.teach_backgrounds.on_put = recovery.background_saver(db, self.cell_id)
        if s.image_max_age_days is not None or s.image_max_bytes is not None:
            from backend.reports import prune_loop

            pruning = asyncio.get_running_loop().create_task(prune_loop(db, s), name="image-prune")
            stack.push_async_callback(_cancel, pruning)

        hardware, cell_world, cell = await assemble_cell(
            stack, s, self._hardware, db=db, cell_id=self.cell_id, bus=self.bus,
            interrupted=interrupted,
        )  # fmt: skip
        self._sim = hardware.sim
        self._world = cell_world
        self._cell = cell
        if s.threshold_follow:
            from backend.recognition.autothreshold import ThresholdKeeper

            keeper = ThresholdKeeper(
                db, self._live_index, cell.jobs, quiet_s=s.threshold_quiet_s,
                backgrounds=lambda: list(self.teach_backgrounds.images.values()),
            )  # fmt: skip
            keeper.start()
            stack.push_async_callback(keeper.stop)
            self.threshold_keeper = keeper
            if len(self._live_index):  # views stored before: a choice from them, if none was
                keeper.changed()

        if self._want_view:
            self.view3d = await start_view3d(
                stack, s, cell, db=db, sim=hardware.sim, bins=cell_world.layout.bins,
                throttle=self.signin_throttle, known=self.known_tokens,
            )  # fmt: skip
        log.info(
            "cell %r (id %d) running: driver=%s camera=%s", s.cell_name, self.cell_id,
            s.driver, s.camera,
        )  # fmt: skip
