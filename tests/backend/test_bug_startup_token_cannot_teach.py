"""The token ``make run`` prints must do the whole tour on a demo cell (teach, inspect,
report): it used to be an operator's, which cannot teach.  On a development cell that
listens on loopback only, ``visioncell serve`` now issues it to the built-in engineer;
in production or on a network address it stays an operator's.  Each start revokes every
earlier start-up token, whichever built-in user held it."""

from __future__ import annotations

import asyncio

import pytest

from backend.auth import authenticate
from backend.cli.users import bootstrap_user, startup_role
from backend.db.session import Database
from tests.utils.factories import TEST_SECRET, make_settings, migrate


@pytest.mark.parametrize(
    ("overrides", "role"),
    [
        ({}, "engineer"),
        ({"http_host": "localhost", "viser_host": "::1"}, "engineer"),
        ({"environment": "production"}, "operator"),
        ({"http_host": "0.0.0.0"}, "operator"),
        ({"viser_host": "192.168.1.20"}, "operator"),
    ],
)
def test_the_start_up_role_follows_the_address_and_the_environment(tmp_path, overrides, role):
    assert startup_role(make_settings(tmp_path, **overrides)) == role


def _user_of(settings, token: str) -> str | None:
    async def run() -> str | None:
        db = Database(settings.database_url)
        try:
            async with db.session() as s:
                user = await authenticate(s, token, TEST_SECRET)
                return None if user is None else f"{user.name}:{user.role}"
        finally:
            await db.dispose()

    return asyncio.run(run())


def test_each_start_revokes_every_earlier_start_up_token(tmp_path):
    settings = make_settings(tmp_path)
    migrate(settings)
    first = asyncio.run(bootstrap_user(settings))
    assert (first.user, first.role) == ("engineer", "engineer")
    assert _user_of(settings, first.token) == "engineer:engineer"
    # The same database started in production: an operator's token, the engineer's revoked.
    second = asyncio.run(bootstrap_user(settings, "operator"))
    assert (second.user, second.role) == ("operator", "operator")
    assert _user_of(settings, first.token) is None
    assert _user_of(settings, second.token) == "operator:operator"
    third = asyncio.run(bootstrap_user(settings))
    assert _user_of(settings, second.token) is None
    assert _user_of(settings, third.token) == "engineer:engineer"
    with pytest.raises(ValueError, match="operator's or an engineer's"):
        asyncio.run(bootstrap_user(settings, "viewer"))
