"""The CLI's side of a running cell: its REST API with a bearer token, and its jobs.

``visioncell models teach`` and ``visioncell inspect once | run`` start a job on the cell
and follow it.  Every job answer of the API (``202`` of the start, ``GET /api/jobs/{id}``)
has the form ``{"job": {...}}``; :func:`job_of` is the one place that unwraps it, so a
change of that envelope shows as a clear error, never as a traceback.
"""

from __future__ import annotations

import json
import time
import urllib.error
import urllib.parse
import urllib.request
from collections.abc import Callable
from typing import Any

import typer

__all__ = [
    "POLL_S",
    "cell_api",
    "fail",
    "follow_job",
    "job_failure",
    "job_of",
    "read_job",
    "request",
]

#: How often a followed job is read again, seconds.
POLL_S = 0.5
#: One request's timeout, seconds (a loaded cell answers within it).
REQUEST_TIMEOUT_S = 30.0
#: The fields every job answer carries (ARCHITECTURE: ``{"id", "state", "progress", "result"}``).
_JOB_FIELDS = ("id", "state", "progress", "message", "result", "created_at")


def fail(message: str) -> typer.Exit:
    """The exit (status 2) of a command that cannot go on, after printing why on stderr."""
    typer.echo(f"error: {message}", err=True)
    return typer.Exit(2)


def cell_api(url: str | None) -> str:
    """The ``.../api`` base of the cell at ``url`` (default: the settings' host and port)."""
    if url is None:
        from backend.cli.common import load_settings

        s = load_settings()
        url = f"http://{s.http_host}:{s.http_port}"
    parts = urllib.parse.urlsplit(url)
    if parts.scheme not in ("http", "https") or not parts.netloc:
        raise fail(f"--url must be http://HOST:PORT or https://HOST:PORT, got {url!r}")
    return url.rstrip("/") + "/api"


def request(url: str, token: str, method: str = "GET", body: Any = None) -> dict[str, Any]:
    """``METHOD url`` with the bearer token and an optional JSON body; the JSON answer.

    An HTTP refusal exits with the API's ``detail``; an unreachable cell exits naming the URL.
    """
    data = None if body is None else json.dumps(body).encode()
    req = urllib.request.Request(url, data=data, method=method)
    req.add_header("Authorization", f"Bearer {token}")
    if data is not None:
        req.add_header("Content-Type", "application/json")
    try:
        with urllib.request.urlopen(req, timeout=REQUEST_TIMEOUT_S) as resp:
            answer = json.loads(resp.read() or b"{}")
    except urllib.error.HTTPError as exc:
        try:
            detail = json.loads(exc.read()).get("detail", "")
        except Exception:
            detail = ""
        raise fail(f"{method} {url}: HTTP {exc.code} {detail}".rstrip()) from None
    except urllib.error.URLError as exc:
        raise fail(f"cannot reach the cell at {url}: {exc.reason}") from None
    except (TimeoutError, json.JSONDecodeError) as exc:
        raise fail(f"{method} {url}: no usable answer ({exc})") from None
    if not isinstance(answer, dict):
        raise fail(f"{method} {url}: expected a JSON object, got {type(answer).__name__}")
    return answer


def job_of(answer: dict[str, Any]) -> dict[str, Any]:
    """The job inside a job answer ``{"job": {...}}``; exits naming what is missing."""
    job = answer.get("job")
    if not isinstance(job, dict) or any(k not in job for k in _JOB_FIELDS):
        keys = sorted(job) if isinstance(job, dict) else sorted(answer)
        raise fail(f"the cell's answer is not a job (fields: {', '.join(keys) or 'none'})")
    return job


def read_job(base: str, token: str, job_id: str) -> dict[str, Any]:
    """``GET /api/jobs/{id}``: the job as it is now."""
    return job_of(request(f"{base}/jobs/{urllib.parse.quote(str(job_id), safe='')}", token))


def follow_job(
    base: str,
    token: str,
    job: dict[str, Any],
    *,
    on_message: Callable[[str], None] | None = None,
    poll_s: float = POLL_S,
    sleep: Callable[[float], None] = time.sleep,
) -> dict[str, Any]:
    """Read ``job`` again every ``poll_s`` until it ends; its last state.

    Each new progress message is printed (or passed to ``on_message``) once, with the
    progress in percent.
    """
    show = on_message or (lambda line: print(line, flush=True))
    last = ""
    while job["state"] == "running":
        message = str(job.get("message") or "")
        if message and message != last:
            last = message
            show(f"{100 * float(job['progress']):5.1f} %  {message}")
        sleep(poll_s)
        job = read_job(base, token, job["id"])
    return job


def job_failure(job: dict[str, Any], what: str) -> typer.Exit:
    """The exit of a job that ended other than ``done``, with its error's detail."""
    err = job.get("error") or {}
    detail = err.get("detail") if isinstance(err, dict) else None
    return fail(f"the {what} {job['state']}: {detail or job.get('message') or 'no detail'}")
