"""Bug: every authenticated request wrote the token's ``last_used_at``, so every read was
a write transaction (on SQLite one writer at a time: readers queued behind inspections
under load).  Now the time is written when it is missing or over a minute old."""

from __future__ import annotations

import asyncio
from datetime import timedelta

from sqlalchemy import select, update

from backend.auth import LAST_USED_RESOLUTION_S
from backend.db.models import ApiToken, User
from backend.db.session import Database


def _last_used(settings, name: str):
    async def run():
        db = Database(settings.database_url)
        try:
            async with db.session() as s:
                return await s.scalar(
                    select(ApiToken.last_used_at).join(User).where(User.name == name)
                )
        finally:
            await db.dispose()

    return asyncio.run(run())


def _age(settings, name: str, seconds: float) -> None:
    async def run():
        db = Database(settings.database_url)
        try:
            async with db.session() as s:
                uid = await s.scalar(select(User.id).where(User.name == name))
                last = await s.scalar(select(ApiToken.last_used_at).where(ApiToken.user_id == uid))
                await s.execute(
                    update(ApiToken)
                    .where(ApiToken.user_id == uid)
                    .values(last_used_at=last - timedelta(seconds=seconds))
                )
        finally:
            await db.dispose()

    asyncio.run(run())


def test_reads_write_last_used_once_a_minute(client, headers, settings):
    assert _last_used(settings, "test-viewer") is None
    assert client.get("/api/robot/state", headers=headers["viewer"]).status_code == 200
    first = _last_used(settings, "test-viewer")
    assert first is not None
    for _ in range(5):
        client.app.state.runtime.auth_cache.clear()  # each sign-in reads the database
        assert client.get("/api/robot/state", headers=headers["viewer"]).status_code == 200
    assert _last_used(settings, "test-viewer") == first  # no write for these reads
    _age(settings, "test-viewer", LAST_USED_RESOLUTION_S + 5)
    aged = _last_used(settings, "test-viewer")
    client.app.state.runtime.auth_cache.clear()  # the next sign-in reads the database
    assert client.get("/api/robot/state", headers=headers["viewer"]).status_code == 200
    assert _last_used(settings, "test-viewer") > aged  # stale: written again
