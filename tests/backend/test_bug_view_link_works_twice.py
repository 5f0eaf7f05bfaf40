"""A console link to the 3D view opens one connection, once: the same link a second time
(within its 120 s) is refused, as are two connections racing with it; two links asked for
in the same second differ, so a second console tab still gets in."""

from __future__ import annotations

import asyncio
import time

import pytest

from backend.db.models import Role
from backend.db.session import Database
from backend.view3d.access import MAX_SPENT_LINKS, ViewAccess, sign_view_link, verify_view_link
from tests.utils.factories import TEST_SECRET

NOW = 1_800_000_000.0


@pytest.fixture
def access(settings, tokens) -> ViewAccess:
    """A view access on the test database (its engine is disposed with the loop)."""
    return ViewAccess(Database(settings.database_url), secret=TEST_SECRET)


async def test_a_link_opens_one_connection_once(access, tokens) -> None:
    link = await access.link_for_token(tokens["operator"])
    assert link is not None
    first = await access.from_link(link)
    assert first is not None and first.role is Role.operator and first.via == "link"
    assert await access.from_link(link) is None
    # Another link for the same token, asked for at once, is a different one and works.
    again = await access.link_for_token(tokens["operator"])
    assert again is not None and again != link
    assert await access.from_link(again) is not None


async def test_two_connections_racing_with_one_link_get_one_grant(access, tokens) -> None:
    link = await access.link_for_token(tokens["viewer"])
    grants = await asyncio.gather(*(access.from_link(link) for _ in range(5)))
    assert sum(g is not None for g in grants) == 1


def test_links_signed_in_the_same_second_differ() -> None:
    a = sign_view_link(token_id=7, user_id=3, role=Role.viewer, secret=TEST_SECRET, now=NOW)
    b = sign_view_link(token_id=7, user_id=3, role=Role.viewer, secret=TEST_SECRET, now=NOW)
    assert a != b
    ca, cb = (verify_view_link(x, secret=TEST_SECRET, now=NOW) for x in (a, b))
    assert ca is not None and cb is not None and ca.nonce != cb.nonce
    with pytest.raises(ValueError, match="nonce"):
        sign_view_link(token_id=7, user_id=3, role=Role.viewer, secret=TEST_SECRET, nonce="x")


async def test_spent_links_are_bounded_and_forgotten_once_expired(access, tokens) -> None:
    link = await access.link_for_token(tokens["viewer"])
    claims = verify_view_link(link, secret=TEST_SECRET)
    assert claims is not None
    # Fill the memory with links that have expired: they are dropped to make room.
    access._spent = {f"{i:016x}": time.time() - 1 for i in range(MAX_SPENT_LINKS)}
    assert await access.from_link(link) is not None
    assert len(access._spent) == 1
    # Full of unexpired ones: a new link is refused rather than an old one forgotten.
    access._spent = {f"{i:016x}": claims.expires_at for i in range(MAX_SPENT_LINKS)}
    fresh = await access.link_for_token(tokens["viewer"])
    assert await access.from_link(fresh) is None
