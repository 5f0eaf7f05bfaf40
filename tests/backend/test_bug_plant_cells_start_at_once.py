"""Regression: two cells of a plant started at the same moment on one database, and one of
them exited at start-up with ``UserExists: user 'operator' already exists``.

Each ``visioncell serve`` issues a start-up token for the built-in operator: if the user is
missing it creates it.  Both processes found it missing, both inserted, and the loser's
unique-index refusal ended the process (seen in CI, ``test_plant_two_processes``).  The
loser now tries once more, finds the operator and issues its token for it.
"""

from __future__ import annotations

import asyncio

from sqlalchemy import func, select

import backend.auth
from backend.auth import Role, authenticate
from backend.cli.users import bootstrap_operator
from backend.db.models import User
from backend.db.session import Database
from tests.utils.factories import make_settings, migrate


def test_the_cell_that_loses_the_race_for_the_operator_still_starts(tmp_path, monkeypatch):
    settings = make_settings(tmp_path)
    migrate(settings)
    secret = settings.secret_key.get_secret_value()
    real = backend.auth.create_user
    calls = {"n": 0}

    async def other_cell_wins(session, name, role, *args, **kw):
        calls["n"] += 1
        if calls["n"] == 1:  # the other cell's commit lands after our check, before our insert
            db = Database(settings.database_url)
            try:
                async with db.session() as other:
                    await real(other, name, role, secret, label="startup")
            finally:
                await db.dispose()
        return await real(session, name, role, *args, **kw)

    monkeypatch.setattr(backend.auth, "create_user", other_cell_wins)
    token = asyncio.run(bootstrap_operator(settings))
    assert calls["n"] == 1  # the second try found the operator and did not create it again

    async def check() -> tuple[int, str | None]:
        db = Database(settings.database_url)
        try:
            async with db.session() as s:
                n = await s.scalar(select(func.count()).select_from(User))
                user = await authenticate(s, token, secret)
                return int(n or 0), None if user is None else user.role
        finally:
            await db.dispose()

    assert asyncio.run(check()) == (1, Role.operator.name)
