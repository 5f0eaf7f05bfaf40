"""Cases run by test_bug_anonymous_viser_client_fills_the_log.py in a process of their own.

An anonymous 3D view client could fill the log with tracebacks: every GUI update viser's
handler fails on (a property the element does not have) left a task exception logged with
its traceback, once per message, and a frame viser cannot decode ended the connection
with another traceback.  Now each client is said once, on one line without a traceback,
its connection stays open, and it can still sign in."""

from __future__ import annotations

import asyncio
import gc
import logging

import pytest

from backend.cell import Cell
from backend.db.session import Database
from backend.view3d import View3D, ViewAccess
from robot.drivers import IdealDriver
from tests.utils.factories import TEST_SECRET, free_port
from tests.utils.viser_client import RawViserClient, uuid_of
from vision.sources import ImageFolderCamera

#: Bounds a hang only; a loaded machine may take long, the test never asserts a speed.
HANG_S = 120.0


@pytest.fixture
async def view(settings, tokens):
    db = Database(settings.database_url)
    cell = Cell(
        settings, IdealDriver(time_scale=20.0), ImageFolderCamera(settings.resolved_camera_folder())
    )
    await cell.start()
    v = View3D(cell, host="127.0.0.1", port=free_port(), access=ViewAccess(db, secret=TEST_SECRET))
    await v.start()
    try:
        yield v, tokens
    finally:
        await v.stop()
        await cell.stop()
        await db.dispose()


async def _until(predicate, what: str) -> None:
    async with asyncio.timeout(HANG_S):
        while not predicate():
            await asyncio.sleep(0.02)


def _guard_lines(caplog) -> list[logging.LogRecord]:
    return [r for r in caplog.records if r.name == "backend.view3d.guard"]


def _tracebacks(caplog) -> list[logging.LogRecord]:
    return [r for r in caplog.records if r.exc_info or "never retrieved" in r.getMessage()]


async def test_bad_messages_are_logged_once_per_client_without_tracebacks(view, caplog) -> None:
    v, tokens = view
    caplog.set_level(logging.INFO)
    async with RawViserClient(v.port) as client:
        await _until(lambda: v.panels, "the client's panel")
        (panel,) = v.panels.values()
        await _until(lambda: "token" in panel.controls, "the sign-in field")
        field, button = uuid_of(panel.controls["token"]), uuid_of(panel.controls["sign_in"])
        for _ in range(30):
            await client.update(field, no_such_property=1)
            await client.update(button, value=[1, 2], another_bad_one="x")
        # Still connected and served: a real sign-in after the garbage works.
        await client.update(field, value=tokens["viewer"])
        await client.press(button)
        await _until(lambda: panel.grant is not None, "the sign-in after the garbage")
        # viser runs each message's handler in a task of its own: the sign-in may be done
        # before the garbage's handlers have failed, so wait for the guard's line
        await _until(lambda: _guard_lines(caplog), "the guard's line about the garbage")
    gc.collect()  # unretrieved task exceptions are reported when the tasks are collected
    await asyncio.sleep(0)
    said = _guard_lines(caplog)
    assert len(said) == 1, [r.getMessage() for r in said]
    assert "GuiUpdateMessage that failed" in said[0].getMessage()
    assert _tracebacks(caplog) == []


async def test_an_undecodable_frame_ends_the_connection_on_one_line(view, caplog) -> None:
    v, _ = view
    caplog.set_level(logging.INFO)

    def ended_count() -> int:
        return sum("connection ended on" in r.getMessage() for r in caplog.records)

    for n, frame in enumerate((b"\x00\x01garbage", {"type": "NoSuchMessage"}), start=1):
        async with RawViserClient(v.port) as client:
            if isinstance(frame, bytes):
                await client._ws.send(frame)
            else:
                await client._send(frame)
            await _until(lambda n=n: ended_count() == n, "the log line")
    ended = [r for r in caplog.records if "connection ended on" in r.getMessage()]
    assert len(ended) == 2 and {r.levelname for r in ended} == {"WARNING"}
    assert "DecodeError" in ended[0].getMessage() and "NoSuchMessage" in ended[1].getMessage()
    gc.collect()
    assert _tracebacks(caplog) == []
