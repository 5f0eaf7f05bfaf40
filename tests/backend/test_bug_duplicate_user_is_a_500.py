"""Regression: creating a user whose name another request had just taken answered 500.

``create_user`` checks the name, then inserts; a second request for the same name that got
between the two (seen in the API fuzz run) hit the unique index and the IntegrityError
became a 500.  A refusal by the index is now the same 409 (``UserExists``) as the check's;
the caller's unit of work is rolled back whole (a savepoint was tried first: on SQLite its
RELEASE committed the user on its own, without the audit row, see ``test_audit``).
"""

from __future__ import annotations

import pytest
from sqlalchemy import select

from backend.auth import Role, UserExists, create_user
from backend.db.models import User
from backend.db.session import Database


async def test_name_taken_between_check_and_insert_is_user_exists(settings, monkeypatch):
    s = settings
    db = Database(s.database_url)
    secret = s.secret_key.get_secret_value()
    try:
        async with db.session() as a:
            await create_user(a, "ann", Role.viewer, secret)
        b_session = db.session()
        with pytest.raises(UserExists, match="ann"):
            async with b_session as b:
                real = b.scalar
                calls = {"n": 0}

                async def check_misses_once(stmt, *args, **kw):
                    calls["n"] += 1
                    if calls["n"] == 1:  # the name check: as if the other commit had not landed
                        return None
                    return await real(stmt, *args, **kw)

                monkeypatch.setattr(b, "scalar", check_misses_once)
                await create_user(b, "ann", Role.viewer, secret)
        monkeypatch.undo()
        async with db.session() as c:  # the failed unit of work left nothing behind
            user, _ = await create_user(c, "bob", Role.viewer, secret)
            assert user.id is not None
            names = (await c.scalars(select(User.name).order_by(User.name))).all()
        assert names == ["ann", "bob"]
    finally:
        await db.dispose()
