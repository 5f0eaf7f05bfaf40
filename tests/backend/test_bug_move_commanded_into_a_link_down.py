"""Bug (found by the fault campaign's motion audit): with the serial link already reported
down by the driver, the inspection under way still commanded its next move (the driver
refused it, the arm did not move, but the cell must not command motion into a link it knows
is down).  Every move the cell executes now checks the driver's link and e-stop first."""

from __future__ import annotations

import dataclasses

import pytest

from robot.errors import LinkDown
from robot.model import ASEA
from robot.trajectory import plan_joint_move


class LinkReportedDown:
    """The cell's driver, its state saying the link is down; counts the moves it gets."""

    def __init__(self, inner):
        self.inner = inner
        self.moves = 0

    def __getattr__(self, name):
        return getattr(self.inner, name)

    @property
    def state(self):
        return dataclasses.replace(self.inner.state, connected=False, fault="disconnected: test")

    async def move(self, traj):
        self.moves += 1
        return await self.inner.move(traj)


def test_no_move_is_commanded_while_the_link_is_down(client, headers):
    cell = client.app.state.runtime.cell
    down = LinkReportedDown(cell.driver)
    cell.driver = down
    traj = plan_joint_move(down.inner.state.q, ASEA.q_ready, speed=1.0)

    async def inspection_step() -> None:
        with cell.jobs.reserve_arm("test"):
            await cell.execute(traj)

    with pytest.raises(LinkDown, match="link is down"):
        client.portal.call(inspection_step)
    r = client.post(
        "/api/robot/move?wait=true",
        json={"joints": [float(v) for v in ASEA.q_ready]},
        headers=headers["operator"],
    )
    assert r.json()["job"]["state"] == "failed", r.text
    assert down.moves == 0  # nothing reached the driver
    cell.driver = down.inner
