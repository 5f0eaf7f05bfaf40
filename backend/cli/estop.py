"""``visioncell estop``: press the running cell's emergency stop from a terminal.

It asks the running cell (``--url``, ``--token`` of any signed-in user) through the REST
API, ``POST /api/robot/estop``, which latches the arm and the conveyors and answers at once
(the token is checked from memory: one the cell has seen signed in within the hour).  It
prints the arm's state after the stop; it exits with 1 when the cell refused or could not
be reached within ``--timeout`` seconds.
"""

from __future__ import annotations

import json
import math
import urllib.error
import urllib.request
from typing import Annotated, Any

import typer

from backend.cli.common import err, load_settings

__all__ = ["estop", "press_estop"]

#: Longest ``--timeout`` accepted, seconds.
MAX_TIMEOUT_S = 60.0


def press_estop(base: str, token: str, *, timeout_s: float = 5.0) -> dict[str, Any]:
    """``POST {base}/api/robot/estop`` with ``token``; the answer's JSON.  Raises
    ``RuntimeError`` with the cell's reason (or why it could not be reached)."""
    req = urllib.request.Request(f"{base.rstrip('/')}/api/robot/estop", data=b"", method="POST")
    req.add_header("Authorization", f"Bearer {token}")
    try:
        with urllib.request.urlopen(req, timeout=timeout_s) as resp:
            return dict(json.loads(resp.read(1 << 20) or b"{}"))
    except urllib.error.HTTPError as exc:
        try:
            detail = json.loads(exc.read(1 << 16)).get("detail", "")
        except Exception:
            detail = ""
        raise RuntimeError(f"the cell refused the E-STOP: HTTP {exc.code} {detail}") from None
    except (urllib.error.URLError, TimeoutError, OSError) as exc:
        reason = getattr(exc, "reason", exc)
        raise RuntimeError(f"cannot reach the cell at {base}: {reason}") from None


def estop(
    token: Annotated[str, typer.Option(help="Any user's token", envvar="VISIONCELL_TOKEN")],
    url: Annotated[str | None, typer.Option(help="Cell URL (default: from the settings)")] = None,
    timeout: Annotated[float, typer.Option(help="Longest wait for the answer, s")] = 5.0,
) -> None:
    """Press the cell's emergency stop (arm and conveyors), latched until a reset."""
    if not (math.isfinite(timeout) and 0.0 < timeout <= MAX_TIMEOUT_S):
        err.print(
            f"[red]error:[/red] --timeout must be in (0, {MAX_TIMEOUT_S:g}] s, got {timeout!r}"
        )
        raise typer.Exit(2)
    if url is None:
        s = load_settings()
        url = f"http://{s.http_host}:{s.http_port}"
    if not url.startswith(("http://", "https://")) or len(url) > 2048:
        err.print(f"[red]error:[/red] --url must be an http(s) URL, got {url[:80]!r}")
        raise typer.Exit(2)
    try:
        answer = press_estop(url, token, timeout_s=timeout)
    except RuntimeError as exc:
        err.print(f"[red]error:[/red] {exc}")
        raise typer.Exit(1) from None
    state = answer.get("state", {})
    print(f"E-STOP latched: estopped={state.get('estopped')} joints={state.get('q')}", flush=True)
