"""The event loop of ``visioncell serve`` (and the load benchmark's server): uvloop when
it is installed, else the standard library's.

uvloop runs the loop's own machinery (sockets, timers, callbacks) in C; the HTTP parser
stays uvicorn's h11 (:mod:`backend.api.limits` needs it for the JSON 400 and 414).
"""

from __future__ import annotations

import asyncio
from collections.abc import Callable, Coroutine
from typing import Any, Literal, TypeVar

__all__ = ["loop_factory", "loop_name", "run"]

T = TypeVar("T")
LoopChoice = Literal["auto", "uvloop", "asyncio"]


def loop_factory(choice: LoopChoice = "auto") -> Callable[[], asyncio.AbstractEventLoop] | None:
    """The ``loop_factory`` of :class:`asyncio.Runner` for ``choice``: uvloop's, or None
    (asyncio's default loop).  ``auto`` falls back to asyncio when uvloop is not
    importable; ``uvloop`` raises :class:`RuntimeError` then."""
    if choice not in ("auto", "uvloop", "asyncio"):
        raise ValueError(f"choice must be 'auto', 'uvloop' or 'asyncio', got {choice!r}")
    if choice == "asyncio":
        return None
    try:
        import uvloop
    except ImportError as exc:
        if choice == "uvloop":
            raise RuntimeError("event loop 'uvloop' asked for: pip install uvloop") from exc
        return None
    return uvloop.new_event_loop


def loop_name(loop: asyncio.AbstractEventLoop) -> str:
    """``uvloop`` or ``asyncio``: which loop ``loop`` is."""
    return "uvloop" if type(loop).__module__.startswith("uvloop") else "asyncio"


def run(main: Coroutine[Any, Any, T], *, choice: LoopChoice = "auto") -> T:
    """Run ``main`` to completion on a new loop chosen by ``choice`` (:func:`loop_factory`)."""
    factory = loop_factory(choice)
    with asyncio.Runner(loop_factory=factory) as runner:
        return runner.run(main)
