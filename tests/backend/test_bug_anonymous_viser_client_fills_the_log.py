"""An anonymous 3D view client could fill the log with tracebacks (the cases, in
``viser_guard_cases.py``: a client's failing messages said once, on one line; an undecodable
frame ends its connection on one line).

The cases run in a process of their own: in the full suite's worker, after other tests, the
guard's line was not seen in the log at all (passing in every smaller combination tried),
so the log the cases read is that of a fresh process, as a served cell's is."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

CASES = Path(__file__).with_name("viser_guard_cases.py")


@pytest.mark.timeout(900)  # a bound on a hang only
def test_a_client_is_said_once_and_an_undecodable_frame_on_one_line():
    r = subprocess.run(
        [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", str(CASES)],
        capture_output=True, text=True, cwd=CASES.parents[2],
        env={**os.environ, "PYTEST_XDIST_WORKER": ""}, check=False,
    )  # fmt: skip
    assert r.returncode == 0, r.stdout[-4000:] + r.stderr[-2000:]
    assert "2 passed" in r.stdout, r.stdout[-2000:]
