"""One 3D view client's own panel: sign-in, and the controls its role allows.

Everything here is built with ``client.gui`` (elements only that one browser sees and only
that browser's websocket can press), so an anonymous client is never sent a motion control
at all.  Each callback checks the client's grant again before it acts.

========  ===========================================================================
role      controls (the same as the REST API)
========  ===========================================================================
(none)    sign-in field; the scene and the shared read-outs only
viewer    E-STOP
operator  E-STOP, Speed, Home, Stop, Reset E-STOP
engineer  as operator, plus the simulated conveyor (run, release) when there is one
========  ===========================================================================
"""

from __future__ import annotations

import asyncio
import logging
import threading
from collections.abc import Callable, Coroutine
from typing import TYPE_CHECKING, Any

import viser

from backend.db.models import Role
from backend.throttle import TooManyAttempts
from backend.view3d.access import ViewAccess, ViewGrant
from vision.errors import VisionCellError

if TYPE_CHECKING:
    from backend.cell import Cell
    from robot.sim import SimEngine

__all__ = ["ClientPanel"]

log = logging.getLogger(__name__)

#: Panel order: the shared read-outs (status, joints) come first.
_ORDER = 100.0


class ClientPanel:
    """The panel of one viser client.

    Parameters
    ----------
    client : viser.ClientHandle
        The connection this panel belongs to.
    cell : Cell
        Target of the buttons (the same methods the REST endpoints call).
    access : ViewAccess or None
        Checks tokens against the database (None: nobody can sign in here).
    loop : asyncio.AbstractEventLoop
        The application's loop (database, cell); callbacks arrive on viser's threads.
    sim : SimEngine, optional
        The simulated cell, for the engineer's conveyor controls.
    """

    def __init__(
        self,
        client: viser.ClientHandle,
        *,
        cell: Cell,
        access: ViewAccess | None,
        loop: asyncio.AbstractEventLoop,
        sim: SimEngine | None = None,
    ) -> None:
        self.client = client
        self.cell = cell
        self.access = access
        #: The browser's address, the key of the sign-in throttle (set by the view).
        self.address = "view3d"
        self.loop = loop
        self.sim = sim
        self._lock = threading.RLock()
        self._grant: ViewGrant | None = None
        self._handles: list[Any] = []
        self._message: Any = None
        self.closed = False
        #: Handles by name for the current controls (``"home"``, ``"token"``, ...).
        self.controls: dict[str, Any] = {}

    # -- grant -----------------------------------------------------------------------------
    @property
    def grant(self) -> ViewGrant | None:
        """The client's grant (None: anonymous)."""
        return self._grant

    def apply(self, grant: ViewGrant | None) -> None:
        """Show the panel for ``grant`` (rebuilds it only if the grant changed)."""
        with self._lock:
            if self.closed:
                return
            if self._handles and grant == self._grant:
                return
            self._grant = grant
            self._rebuild()

    def close(self) -> None:
        """Forget the client (it disconnected)."""
        with self._lock:
            self.closed = True
            self._grant = None
            self._handles.clear()
            self.controls.clear()

    def allows(self, role: Role) -> bool:
        """True if the client currently holds at least ``role``."""
        grant = self._grant
        return grant is not None and grant.allows(role)

    # -- building ----------------------------------------------------------------------------
    def _rebuild(self) -> None:
        for handle in self._handles:
            handle.remove()
        self._handles.clear()
        self.controls.clear()
        gui = self.client.gui
        grant = self._grant
        folder = gui.add_folder("Access", order=_ORDER)
        self._handles.append(folder)
        with folder:
            if grant is None and self.access is None:
                self._add(
                    "who", gui.add_markdown("Sign-in is not configured: you see the cell only.")
                )
            elif grant is None:
                self._add("who", gui.add_markdown("Not signed in: you see the cell only."))
                self._add(
                    "token", gui.add_text("API token", "", hint="vc_... from `visioncell user add`")
                )
                self._add("sign_in", gui.add_button("Sign in")).on_click(self._on_sign_in)
            else:
                how = {"token": "token", "link": "console link", "open": "no auth"}[grant.via]
                self._add(
                    "who",
                    gui.add_markdown(f"Signed in as **{grant.user}** ({grant.role.name}, {how})"),
                )
                if grant.via != "open":
                    self._add("sign_out", gui.add_button("Sign out")).on_click(self._on_sign_out)
        self._message = self._add("message", gui.add_markdown("", order=_ORDER + 1))
        self._handles.append(self._message)
        if grant is None:
            return
        ctl = gui.add_folder("Robot", order=_ORDER + 2)
        self._handles.append(ctl)
        with ctl:
            self._add("estop", gui.add_button("E-STOP", color="red")).on_click(
                self._guarded(Role.viewer, self._estop)
            )
            if grant.allows(Role.operator):
                speed = self._add(
                    "speed",
                    gui.add_slider(
                        "Speed", min=0.05, max=1.0, step=0.05, initial_value=self.cell.speed
                    ),
                )
                speed.on_update(self._on_speed)
                self._add("home", gui.add_button("Home")).on_click(
                    self._guarded(Role.operator, self._home)
                )
                self._add("stop", gui.add_button("Stop")).on_click(
                    self._guarded(Role.operator, self.cell.stop_motion)
                )
                self._add("reset", gui.add_button("Reset E-STOP")).on_click(
                    self._guarded(Role.operator, self._reset)
                )
        if grant.allows(Role.engineer) and self.sim is not None:
            belt = gui.add_folder("Conveyor (engineer)", order=_ORDER + 3)
            self._handles.append(belt)
            with belt:
                running = self._add(
                    "conveyor_running",
                    gui.add_checkbox("Running", initial_value=self.sim.conveyor_state.running),
                )
                running.on_update(self._on_conveyor)
                self._add("conveyor_release", gui.add_button("Release")).on_click(
                    self._guarded(Role.engineer, self._release)
                )

    def _who(self) -> tuple[str, str]:
        """The signed-in user's name and role name (for the E-STOP's record)."""
        grant = self._grant
        return ("system", "system") if grant is None else (grant.user, grant.role.name)

    async def _estop(self) -> None:
        by, role = self._who()
        await self.cell.estop(by=by, role=role, source="view3d")

    async def _reset(self) -> None:
        by, role = self._who()
        await self.cell.reset(by=by, role=role, source="view3d")

    def _add(self, name: str, handle: Any) -> Any:
        # Only top-level elements are removed on a rebuild; a folder takes its children.
        self.controls[name] = handle
        return handle

    # -- callbacks (viser's threads) ------------------------------------------------------------
    def _mine(self, event: Any) -> bool:
        return getattr(event, "client_id", None) == self.client.client_id

    def _guarded(
        self, role: Role, action: Callable[[], Coroutine[Any, Any, Any]]
    ) -> Callable[[Any], None]:
        def on_click(event: Any) -> None:
            if not self._mine(event) or not self.allows(role):
                self.say(f"**Refused:** this needs the {role.name} role")
                return
            self.submit(action())

        return on_click

    def _on_speed(self, event: Any) -> None:
        handle = self.controls.get("speed")
        if handle is None or not self._mine(event) or not self.allows(Role.operator):
            return
        value = float(handle.value)
        if 0.05 <= value <= 1.0:
            self.cell.speed = value

    def _on_conveyor(self, event: Any) -> None:
        handle = self.controls.get("conveyor_running")
        if (
            handle is None
            or self.sim is None
            or not self._mine(event)
            or not self.allows(Role.engineer)
        ):
            return
        running = bool(handle.value)
        sim = self.sim

        async def configure() -> None:
            await asyncio.to_thread(sim.configure_conveyor, running=running)

        self.submit(configure())

    async def _home(self) -> None:
        self.cell.home()

    async def _release(self) -> None:
        if self.sim is not None:
            await asyncio.to_thread(self.sim.release_conveyor)

    def _on_sign_in(self, event: Any) -> None:
        field = self.controls.get("token")
        if field is None or not self._mine(event):
            return
        token = str(field.value)
        field.value = ""  # viser's text input has no password mode: do not leave it shown
        if not token.strip():
            self.say("Paste an API token first.")
            return

        access = self.access
        if access is None:
            return

        async def sign_in() -> None:
            try:
                grant = await access.from_token(token, client=self.address)
            except TooManyAttempts as exc:
                self.say(f"**Too many failed sign-ins:** try again in {exc.retry_after_s} s.")
                return
            if grant is None:
                self.say("**That token is not valid.**")
                return
            self.apply(grant)

        self.submit(sign_in(), clear=False)

    def _on_sign_out(self, event: Any) -> None:
        if self._mine(event):
            self.apply(None)

    # -- helpers --------------------------------------------------------------------------------
    def say(self, text: str) -> None:
        """Show ``text`` under the access folder."""
        with self._lock:
            if self._message is not None and not self.closed:
                self._message.content = text

    def submit(self, coro: Coroutine[Any, Any, Any], *, clear: bool = True) -> None:
        """Run ``coro`` on the application loop; a refusal is shown in the panel."""
        fut = asyncio.run_coroutine_threadsafe(coro, self.loop)

        def done(f: Any) -> None:
            exc = f.exception()
            if exc is not None:
                if not isinstance(exc, VisionCellError | ValueError):
                    log.warning("3D view action failed: %r", exc)
                text = exc.detail if isinstance(exc, VisionCellError) else str(exc)
                self.say(f"**Refused:** {text}")
            elif clear:
                self.say("")

        fut.add_done_callback(done)
