"""Bug (the operator's path): ``visioncell serve`` took 6.0 s and 4.9 s to exit after Ctrl-C
(the README says about a second).  The cell itself stopped in a fraction of a second; the
rest was the interpreter's final garbage collection of the modules' objects (the simulator,
the index, the 3D view), with nothing left to close.  Now the process ends once the cell has
stopped cleanly.

The test serves the simulated cell with a console's live socket, the 3D view and a REST
client attached (token from ``visioncell user add``), sends SIGINT or SIGTERM, and checks that
the process exits cleanly and leaves no child process behind; the timeout only bounds a hang.
"""

from __future__ import annotations

import json
import os
import signal
import time
from pathlib import Path

import httpx
import pytest
from websockets.sync.client import connect

from tests.e2e.conftest import start_server

pytestmark = pytest.mark.slow


def _children(pid: int) -> list[int]:
    """Processes whose parent is ``pid`` (from /proc)."""
    out = []
    for d in Path("/proc").iterdir():
        if not d.name.isdigit():
            continue
        try:
            fields = (d / "stat").read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        if int(fields[1]) == pid:
            out.append(int(d.name))
    return out


def _alive(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except OSError:
        return False
    return state != "Z"


#: SIGINT (Ctrl-C) on the simulated demo cell, SIGTERM on the ideal arm and a folder camera.
CASES = [
    (signal.SIGINT, {"VISIONCELL_DRIVER": "sim", "VISIONCELL_CAMERA": "sim"}),
    (signal.SIGTERM, {}),
]


@pytest.mark.parametrize(("sig", "env"), CASES, ids=["SIGINT-sim", "SIGTERM-ideal"])
def test_a_served_cell_stops_on_a_signal_and_leaves_nothing_behind(tmp_path, sig, env):
    server = start_server(tmp_path, ready_s=300.0, VISIONCELL_VIEW3D_ENABLED="true", **env)
    proc = server.proc
    try:
        token = server.token("olga", "operator")
        head = {"Authorization": f"Bearer {token}"}
        assert httpx.get(f"{server.base}/api/belt", headers=head, timeout=30).status_code == 200
        ws_url = server.base.replace("http://", "ws://") + "/api/ws"
        with (
            connect(ws_url, open_timeout=30) as live,
            connect(server.viser.replace("http://", "ws://"), open_timeout=30),
        ):
            live.send(json.dumps({"token": token}))
            live.recv(timeout=30)  # the console's socket is open and served
            children = _children(proc.pid)
            t0 = time.monotonic()
            proc.send_signal(sig)
            rc = proc.wait(timeout=120)  # bounds a hang only
            took = time.monotonic() - t0
        log = server.log.read_text()
        assert rc == 0, (rc, log[-2000:])
        assert "Traceback" not in log, log[-3000:]
        assert not [c for c in children if _alive(c)], children
        print(f"{signal.Signals(sig).name}: exited in {took:.2f} s")
    finally:
        if proc.poll() is None:
            os.kill(proc.pid, signal.SIGKILL)
            proc.wait(timeout=30)
