"""The README's CLI against a running cell: ``visioncell models teach NAME --token T``,
``visioncell inspect once --token T`` and ``visioncell inspect run --token T --count 1``
each follow their job to the end and print its outcome.

They used to stop at once with ``KeyError: 'state'``: ``GET /api/jobs/{id}`` answers
``{"job": {...}}`` and the commands read the envelope as the job.  Here every command runs
as a subprocess against ``visioncell serve`` (the simulated cell, started on free ports),
with the token ``visioncell user add`` printed, as a user runs them.
"""

from __future__ import annotations

import re
import subprocess
import sys
import threading

import httpx
import pytest

from backend.cli.remote import job_of
from robot.sim.world import ConveyorSpec
from tests.e2e.conftest import Server, start_server

# The simulated cell teaches and inspects: about a minute on an idle machine, far more on
# a shared one; every wait below only bounds a hang.
pytestmark = [pytest.mark.e2e, pytest.mark.slow, pytest.mark.timeout(1800)]

STATION = ConveyorSpec().station_s_m
REQUEST_S = 30.0
COMMAND_S = 900.0
PART = "wheel-steel"


def _cli(s: Server, *args: str, timeout: float = COMMAND_S) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "backend.cli", *args],
        capture_output=True,
        text=True,
        env=s.env,
        timeout=timeout,
    )


def _clear_station(s: Server, hdr: dict[str, str]) -> None:
    r = httpx.post(f"{s.base}/api/sim/conveyor", json={"running": False, "mode": "index"},
                   headers=hdr, timeout=REQUEST_S)  # fmt: skip
    assert r.status_code == 200, r.text
    for obj in httpx.get(f"{s.base}/api/sim/objects", headers=hdr, timeout=REQUEST_S).json()[
        "data"
    ]:
        httpx.delete(f"{s.base}/api/sim/objects/{obj['id']}", headers=hdr, timeout=REQUEST_S)


@pytest.fixture(scope="module")
def cell(tmp_path_factory):
    s = start_server(
        tmp_path_factory.mktemp("cli-cell"),
        ready_s=300.0,
        VISIONCELL_DRIVER="sim",
        VISIONCELL_CAMERA="sim",
        VISIONCELL_SIM_DEMO="false",
        VISIONCELL_TIME_SCALE="5",
        VISIONCELL_CAMERA_FPS="4",
        VISIONCELL_VIEW3D_ENABLED="false",
    )
    yield s
    s.stop()


def test_job_of_unwraps_the_envelope_and_names_a_bad_answer(capsys):
    job = {
        "id": "j1",
        "state": "running",
        "progress": 0.0,
        "message": "",
        "result": None,
        "created_at": "2026-12-06T00:00:00+00:00",
    }
    assert job_of({"job": job}) is job
    import typer

    with pytest.raises(typer.Exit):
        job_of(job)  # the job itself where its envelope belongs
    assert "not a job" in capsys.readouterr().err


def _banner_token(s: Server) -> str:
    """The start-up token ``visioncell serve`` printed (as ``make run`` shows it)."""
    lines = s.log.read_text().splitlines()
    at = next(
        i for i, line in enumerate(lines) if line.strip().endswith("valid until the next start):")
    )
    assert lines[at].strip().startswith("engineer token")  # a loopback development cell
    return lines[at + 1].strip()


def test_teach_and_inspect_commands_follow_their_jobs(cell: Server):
    # The token `make run` prints teaches; an operator's from `visioncell user add` inspects.
    token = _banner_token(cell)
    operator = cell.token("cli-operator", "operator")  # the last line of `visioncell user add`
    hdr = {"Authorization": f"Bearer {token}"}
    url = ["--url", cell.base]

    # Nothing taught yet: the command names the way to teach, without a traceback.
    r = _cli(cell, "inspect", "once", "--token", operator, *url, "--policy", "top-only")
    assert r.returncode == 2, r.stdout + r.stderr
    assert "Traceback" not in r.stderr and "teach a model first" in r.stderr

    r = _cli(cell, "models", "add", PART, "--kind", "2d")
    assert r.returncode == 0, r.stderr
    _clear_station(cell, hdr)

    # The teach grabs the empty station, then waits for the object: place it when it says so.
    teach = subprocess.Popen(
        [sys.executable, "-m", "backend.cli", "models", "teach", PART, "--token", token, *url,
         "--wait", "300"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=cell.env,
    )  # fmt: skip
    lines: list[str] = []
    waiting = threading.Event()

    def read() -> None:
        assert teach.stdout is not None
        for line in teach.stdout:
            lines.append(line)
            if "waiting for an object" in line:
                waiting.set()

    reader = threading.Thread(target=read, daemon=True)
    reader.start()
    try:
        assert waiting.wait(COMMAND_S), "".join(lines)
        r2 = httpx.post(f"{cell.base}/api/sim/objects", headers=hdr, timeout=REQUEST_S,
                        json={"name": PART, "position_along_belt_m": STATION})  # fmt: skip
        assert r2.status_code == 201, r2.text
        teach.wait(COMMAND_S)
    finally:
        if teach.poll() is None:
            teach.kill()
    reader.join(REQUEST_S)
    err = teach.stderr.read() if teach.stderr else ""
    out = "".join(lines)
    assert teach.returncode == 0, out + err
    assert "Traceback" not in err and "KeyError" not in err
    # the job's progress, as it went (a 2d model's teach adds a side view for the height)
    assert re.search(r"%  view 1/\d+: viewpoint 1", out), out
    assert f"taught 3 views of {PART!r}" in out
    assert "the one round a 2d model needs is taught" in out  # the rounds its kind needs
    assert "('" not in out  # no Python tuple in the threshold's reason

    # The object is still at the station: inspect it once, then a run of one object.
    r = _cli(cell, "inspect", "once", "--token", operator, *url, "--policy", "top-only")
    assert r.returncode == 0, r.stdout + r.stderr
    last = r.stdout.strip().splitlines()[-1]
    assert last.startswith("#") and f"recognized {PART}" in last, r.stdout

    r = _cli(cell, "inspect", "run", "--token", operator, *url, "--policy", "top-only",
             "--count", "1")  # fmt: skip
    assert r.returncode == 0, r.stdout + r.stderr
    out = r.stdout.strip().splitlines()
    assert out[-1].startswith("inspected 1: "), r.stdout
    rows = [line for line in out if line.startswith("#")]
    assert len(rows) == 1, r.stdout  # the run's own inspection, printed once

    # Each printed row is a stored inspection.
    first_id = int(last.split()[0][1:])
    run_id = int(rows[0].split()[0][1:])
    assert run_id > first_id
    got = httpx.get(f"{cell.base}/api/inspections/{run_id}", headers=hdr, timeout=REQUEST_S)
    assert got.status_code == 200 and got.json()["id"] == run_id
