"""Regression: creating a user whose name another request had just taken answered 500.

``create_user`` checks the name, then inserts; a second request for the same name that got
between the two (seen in the API fuzz run) hit the unique index and the IntegrityError
became a 500.  The insert now runs in a savepoint and a refusal by the index is the same 409
(``UserExists``) as the check's, and the session stays usable.
"""

from __future__ import annotations

import pytest

from backend.auth import Role, UserExists, create_user
from backend.db.session import Database


async def test_name_taken_between_check_and_insert_is_user_exists(settings, monkeypatch):
    s = settings
    db = Database(s.database_url)
    secret = s.secret_key.get_secret_value()
    try:
        async with db.session() as a:
            await create_user(a, "ann", Role.viewer, secret)
        async with db.session() as b:
            real = b.scalar
            calls = {"n": 0}

            async def check_misses_once(stmt, *args, **kw):
                calls["n"] += 1
                if calls["n"] == 1:  # the name check: as if the other commit had not landed
                    return None
                return await real(stmt, *args, **kw)

            monkeypatch.setattr(b, "scalar", check_misses_once)
            with pytest.raises(UserExists, match="ann"):
                await create_user(b, "ann", Role.viewer, secret)
            monkeypatch.undo()
            user, _ = await create_user(b, "bob", Role.viewer, secret)  # session still usable
            assert user.id is not None
    finally:
        await db.dispose()
