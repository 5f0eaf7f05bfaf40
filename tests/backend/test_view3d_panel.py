"""The 3D view's per-client panel over viser's real websocket: anonymous clients move nothing,
signed-in clients get the controls of their role, revocation takes them away."""

from __future__ import annotations

import asyncio
import time

import numpy as np
import pytest

from backend.auth import revoke_tokens
from backend.cell import Cell
from backend.db.models import Role, User
from backend.db.session import Database
from backend.view3d import View3D, ViewAccess
from backend.view3d.access import LINK_PATH_PREFIX, sign_view_link
from robot.drivers import IdealDriver
from robot.model import ASEA
from tests.utils.factories import TEST_SECRET, free_port
from tests.utils.viser_client import RawViserClient, uuid_of
from vision.sources import ImageFolderCamera

ANONYMOUS_CONTROLS = {"who", "token", "sign_in", "message"}


@pytest.fixture
async def rig(settings, tokens):
    db = Database(settings.database_url)
    cell = Cell(
        settings, IdealDriver(time_scale=20.0), ImageFolderCamera(settings.resolved_camera_folder())
    )
    await cell.start()
    view = View3D(
        cell,
        host="127.0.0.1",
        port=free_port(),
        access=ViewAccess(db, secret=TEST_SECRET),
        recheck_s=0.2,
    )
    await view.start()
    try:
        yield view, cell, db, tokens
    finally:
        await view.stop()
        await cell.stop()
        await db.dispose()


async def _until(predicate, timeout: float = 10.0, what: str = "condition") -> None:
    deadline = time.monotonic() + timeout
    while not predicate():
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out waiting for {what}")
        await asyncio.sleep(0.02)


def _shown(panel) -> set[str]:
    """The panel's controls, read while no rebuild is under way: a sign-out drops the
    grant first (every guarded callback refuses from then on) and then rebuilds the
    controls on viser's thread, so the two can be seen apart for a moment."""
    with panel._lock:
        return set(panel.controls)


async def _anonymous(panel, what: str) -> None:
    await _until(lambda: panel.grant is None and _shown(panel) == ANONYMOUS_CONTROLS, what=what)


async def _panel(view: View3D, known: set[int]):
    await _until(lambda: set(view.panels) - known, what="the client's panel")
    (cid,) = set(view.panels) - known
    return view.panels[cid]


async def _sign_in(client: RawViserClient, panel, token: str) -> None:
    await client.update(uuid_of(panel.controls["token"]), value=token)
    await client.press(uuid_of(panel.controls["sign_in"]))


async def _move_to_ready(cell: Cell) -> None:
    job = cell.move_joints(ASEA.q_ready, speed=1.0)
    await cell.jobs.wait(job)
    assert job.state.value == "done", job.public()


async def test_an_anonymous_client_moves_nothing(rig):
    view, cell, _, tokens = rig
    await _move_to_ready(cell)
    jobs_before = len(cell.jobs.list())
    async with RawViserClient(view.port) as op_client:
        op = await _panel(view, set())
        await _sign_in(op_client, op, tokens["operator"])
        await _until(lambda: "home" in op.controls, what="the operator's controls")
        async with RawViserClient(view.port) as anon_client:
            anon = await _panel(view, {op.client.client_id})
            assert anon.grant is None
            assert set(anon.controls) == ANONYMOUS_CONTROLS  # never sent a control
            # The shared panel holds read-outs only: no input anyone could press or set.
            shared = list(view.server.gui._gui_input_handle_from_uuid)
            assert shared == []
            # A hostile client presses what it can name: the operator's own buttons (by
            # uuid), then moves the operator's speed slider.
            theirs = [uuid_of(op.controls[k]) for k in ("home", "estop", "reset", "stop")]
            for uuid in shared + theirs:
                await anon_client.press(uuid)
            await anon_client.update(uuid_of(op.controls["speed"]), value=0.05)
            await anon_client.update(uuid_of(anon.controls["token"]), value="vc_guess")
            await anon_client.press(uuid_of(anon.controls["sign_in"]))
            await asyncio.sleep(1.0)
            assert anon.grant is None
            assert "not valid" in anon.controls["message"].content
    state = cell.driver.state
    np.testing.assert_allclose(state.q, ASEA.q_ready, atol=1e-9)
    assert not state.estopped and not state.moving
    assert len(cell.jobs.list()) == jobs_before
    assert cell.speed == 0.5


async def test_a_signed_in_operator_moves_the_arm_and_loses_control_on_revocation(rig):
    view, cell, db, tokens = rig
    await _move_to_ready(cell)
    async with RawViserClient(view.port) as client:
        panel = await _panel(view, set())
        await _sign_in(client, panel, tokens["operator"])
        await _until(lambda: "home" in panel.controls, what="the operator's controls")
        assert panel.grant is not None and panel.grant.role is Role.operator
        assert "token" not in panel.controls
        assert "conveyor_running" not in panel.controls  # engineer-only (and no simulator)
        await client.press(uuid_of(panel.controls["home"]))
        await _until(
            lambda: (
                np.allclose(cell.driver.state.q, ASEA.q_home, atol=1e-6)
                and not cell.driver.state.moving
            ),
            what="the arm at home",
        )
        await client.press(uuid_of(panel.controls["estop"]))
        await _until(lambda: cell.driver.state.estopped, what="the e-stop")
        await client.press(uuid_of(panel.controls["reset"]))
        await _until(lambda: not cell.driver.state.estopped, what="the reset")
        await client.update(uuid_of(panel.controls["speed"]), value=0.25)
        await _until(lambda: cell.speed == 0.25, what="the new speed")

        async with db.session() as s:
            user = await s.get(User, 2)
            assert user is not None and user.name == "test-operator"
            await revoke_tokens(s, user)
        await _anonymous(panel, "revocation to reach the panel")
        assert "revoked" in panel.controls["message"].content


async def test_a_viewer_may_press_estop_only_and_sign_out_removes_it(rig):
    view, cell, _, tokens = rig
    async with RawViserClient(view.port) as client:
        panel = await _panel(view, set())
        await _sign_in(client, panel, tokens["viewer"])
        await _until(lambda: "estop" in panel.controls, what="the viewer's controls")
        assert {"home", "reset", "speed", "stop"}.isdisjoint(panel.controls)
        await client.press(uuid_of(panel.controls["estop"]))
        await _until(lambda: cell.driver.state.estopped, what="the e-stop")
        await client.press(uuid_of(panel.controls["sign_out"]))
        await _anonymous(panel, "sign-out")
    assert cell.driver.state.estopped  # nobody without the operator role reset it


async def test_the_console_link_signs_the_client_in_and_bad_links_do_not(rig):
    view, cell, _, tokens = rig
    assert view.access is not None
    link = await view.access.link_for_token(tokens["engineer"])
    assert link is not None
    async with RawViserClient(view.port, path=LINK_PATH_PREFIX + link) as client:
        panel = await _panel(view, set())
        await _until(lambda: panel.grant is not None, what="the link's grant")
        assert panel.grant.role is Role.engineer and panel.grant.via == "link"
        assert {"home", "reset", "estop", "sign_out"} <= set(panel.controls)
        await _move_to_ready(cell)
        await client.press(uuid_of(panel.controls["home"]))
        await _until(
            lambda: np.allclose(cell.driver.state.q, ASEA.q_home, atol=1e-6),
            what="the arm at home",
        )
        known = {panel.client.client_id}
        expired = sign_view_link(
            token_id=panel.grant.token_id,
            user_id=3,
            role=Role.engineer,
            secret=TEST_SECRET,
            ttl_s=1.0,
            now=time.time() - 10,
        )
        for bad in (expired, link[:-2] + "zz", "v1.garbage"):
            async with RawViserClient(view.port, path=LINK_PATH_PREFIX + bad):
                other = await _panel(view, known)
                known.add(other.client.client_id)
                await _until(
                    lambda o=other: "expired" in o.controls["message"].content,
                    what="the refusal of a bad link",
                )
                assert other.grant is None and set(other.controls) == ANONYMOUS_CONTROLS


async def test_a_view_without_access_shows_no_controls(settings, tmp_path):
    cell = Cell(
        settings, IdealDriver(time_scale=20.0), ImageFolderCamera(settings.resolved_camera_folder())
    )
    await cell.start()
    view = View3D(cell, host="127.0.0.1", port=free_port())
    await view.start()
    try:
        async with RawViserClient(view.port):
            panel = await _panel(view, set())
            assert set(panel.controls) == {"who", "message"}
    finally:
        await view.stop()
        await cell.stop()


async def test_without_auth_every_client_gets_the_engineer_panel(settings):
    db = Database(settings.database_url)
    cell = Cell(
        settings, IdealDriver(time_scale=20.0), ImageFolderCamera(settings.resolved_camera_folder())
    )
    await cell.start()
    view = View3D(
        cell,
        host="127.0.0.1",
        port=free_port(),
        access=ViewAccess(db, secret=TEST_SECRET, auth_enabled=False),
    )
    await view.start()
    try:
        async with RawViserClient(view.port):
            panel = await _panel(view, set())
            assert panel.grant is not None and panel.grant.via == "open"
            assert {"home", "reset", "estop"} <= set(panel.controls)
            assert "sign_out" not in panel.controls
    finally:
        await view.stop()
        await cell.stop()
        await db.dispose()


class _FakeBelt:
    """Stands in for the simulator's conveyor (the MuJoCo cell has its own tests)."""

    def __init__(self) -> None:
        self.running = False
        self.releases = 0

    @property
    def conveyor_state(self):
        return self

    def configure_conveyor(self, *, running: bool) -> None:
        self.running = running

    def release_conveyor(self) -> None:
        self.releases += 1


async def test_only_engineers_get_the_conveyor_controls(rig):
    view, _, _, tokens = rig
    belt = _FakeBelt()
    view.sim = belt  # read by the panels of clients that connect from now on
    async with RawViserClient(view.port) as op_client:
        op = await _panel(view, set())
        async with RawViserClient(view.port) as eng_client:
            eng = await _panel(view, {op.client.client_id})
            await _sign_in(op_client, op, tokens["operator"])
            await _sign_in(eng_client, eng, tokens["engineer"])
            await _until(lambda: "home" in op.controls and "home" in eng.controls, what="sign-in")
            await _engineer_and_operator(belt, op, eng, op_client, eng_client)


async def _engineer_and_operator(belt, op, eng, op_client, eng_client) -> None:
    """The engineer runs the belt; the operator's connection cannot reach those controls."""
    assert "conveyor_running" not in op.controls and "conveyor_release" not in op.controls
    await eng_client.update(uuid_of(eng.controls["conveyor_running"]), value=True)
    await _until(lambda: belt.running, what="the belt to start")
    await eng_client.press(uuid_of(eng.controls["conveyor_release"]))
    await _until(lambda: belt.releases == 1, what="the release")
    # The operator's connection cannot reach the engineer's controls.
    await op_client.update(uuid_of(eng.controls["conveyor_running"]), value=False)
    await op_client.press(uuid_of(eng.controls["conveyor_release"]))
    await asyncio.sleep(0.5)
    assert belt.running and belt.releases == 1
