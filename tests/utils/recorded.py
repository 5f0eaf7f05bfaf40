"""Factories for cells without the simulator: COIL-20 images as camera folders and trained
views, recorded sequences, and waiting for a job over REST."""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import pytest

#: Longest wait for one job in these tests: only a bound on a hang (a loaded machine may be
#: slow, never this slow).
JOB_WAIT_S = 600.0


def coil_dir(data_dir: Path) -> Path:
    """The COIL-20 folder of the public data, or skip the test saying where it was looked for."""
    folder = data_dir / "recognition" / "coil20"
    if not (folder / "obj1__0.png").is_file():
        pytest.skip(f"COIL-20 is absent from {folder} (see the data README)")
    return folder


def coil_file(coil: Path, obj: int, k: int) -> Path:
    """COIL-20 image of object ``obj`` at turntable step ``k`` (angle 5 k degrees)."""
    return coil / f"obj{obj}__{k}.png"


def link_sequence(folder: Path, files: list[Path]) -> Path:
    """A camera folder replaying ``files`` in this order (symbolic links named ``0000_...``
    so that the name order is the sequence; the data stays where it is)."""
    folder.mkdir(parents=True, exist_ok=True)
    for i, f in enumerate(files):
        (folder / f"{i:04d}_{f.name}").symlink_to(f)
    return folder


def upload_views(client: Any, headers: dict[str, str], model_id: int, files: list[Path]) -> Any:
    """Upload ``files`` as top views of ``model_id`` (``POST /api/models/{id}/views``)."""
    parts = [("images", (f.name, f.read_bytes(), "image/png")) for f in files]
    return client.post(
        f"/api/models/{model_id}/views",
        files=parts,
        data={"viewpoints": "1"},
        headers=headers,
    )


def wait_job(client: Any, headers: dict[str, str], job_id: Any) -> dict[str, Any]:
    """Poll ``GET /api/jobs/{id}`` until the job has ended; returns it."""
    deadline = time.monotonic() + JOB_WAIT_S
    while True:
        job = client.get(f"/api/jobs/{job_id}", headers=headers).json()["job"]
        if job["state"] != "running":
            return job
        assert time.monotonic() < deadline, f"job {job_id} still {job['state']}: {job}"
        time.sleep(0.2)
