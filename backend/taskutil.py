"""Stopping a background task for sure.

``task.cancel()`` followed by ``await task`` can wait forever on Python 3.11: when the
task is inside ``asyncio.wait_for`` and the awaited operation finishes in the same loop
iteration as the cancellation arrives, ``wait_for`` returns the result and the
cancellation is lost (CPython issue gh-86296, fixed by the rewrite of ``wait_for`` in
3.12); a supervised loop then simply goes on.  :func:`cancel_and_wait` cancels again until
the task has ended.
"""

from __future__ import annotations

import asyncio
import contextlib
from typing import Any

__all__ = ["cancel_and_wait"]


async def cancel_and_wait(task: asyncio.Task[Any], *, every_s: float = 0.5) -> None:
    """Cancel ``task`` and wait for its end, cancelling again every ``every_s`` seconds
    while it is still running (a cancellation swallowed by ``wait_for``)."""
    if not 0.0 < float(every_s) <= 60.0:
        raise ValueError(f"every_s must be within (0, 60] s, got {every_s!r}")
    while not task.done():
        task.cancel()
        await asyncio.wait({task}, timeout=every_s)
    with contextlib.suppress(asyncio.CancelledError):
        task.result()
