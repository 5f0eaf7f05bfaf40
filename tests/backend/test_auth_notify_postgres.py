"""Sign-in changes reach the other processes of a plant at once (PostgreSQL LISTEN/NOTIFY):
a token revoked, or a user disabled, through one process's database is dropped from
another process's sign-in cache within a second, long before its TTL; other users'
entries stay; the TTL stays the fallback when nothing listens.

"Another process" is a second :class:`Database` with its own :class:`AuthCache`, not
hooked to the first database's sessions, so only the notification can reach it."""

from __future__ import annotations

import asyncio
import time

import pytest
from sqlalchemy import select

from backend.auth import authenticate_with_expiry, create_user, hash_token, revoke_tokens
from backend.authsync import AuthSync
from backend.caches import AuthCache, parse_payload, users_changed
from backend.db.models import Role, User
from backend.db.session import Database

SECRET = "auth-notify-secret-0123456789abcdef"
TTL_S = 30.0  # far longer than the test waits: only a notification can drop an entry


class Plant:
    """Two processes of one plant on ``url``: A changes sign-ins, B caches them."""

    def __init__(self, url: str, clock=None) -> None:
        self.a, self.b = Database(url), Database(url)
        self.cache_b = AuthCache(ttl_s=TTL_S) if clock is None else AuthCache(clock=clock)

    async def add_user(self, name: str) -> tuple[int, str]:
        async with self.a.session() as s:
            user, token = await create_user(s, name, Role.operator, SECRET)
            return int(user.id), token

    async def sign_in_b(self, token: str) -> str:
        """B reads the sign-in from the database and caches it; returns its key."""
        key = hash_token(token, SECRET)
        gen = self.cache_b.generation
        async with self.b.session() as s:
            found = await authenticate_with_expiry(s, token, SECRET)
        assert found is not None
        self.cache_b.put(key, found[0], found[1], generation=gen)
        assert self.cache_b.get(key) is not None
        return key

    async def gone_from_b(self, key: str, within_s: float) -> bool:
        t0 = time.monotonic()
        while time.monotonic() - t0 < within_s:
            if self.cache_b.get(key) is None:
                return True
            await asyncio.sleep(0.02)
        return False

    async def close(self) -> None:
        await self.a.dispose()
        await self.b.dispose()


def test_revocation_and_disabling_reach_the_other_process_at_once(postgres_url):
    async def main() -> None:
        plant = Plant(postgres_url)
        sync = AuthSync(postgres_url, plant.cache_b)
        sync.start()
        try:
            await asyncio.wait_for(sync.ready.wait(), 10)
            uid1, tok1 = await plant.add_user("alice")
            uid2, tok2 = await plant.add_user("bob")
            k1, k2 = await plant.sign_in_b(tok1), await plant.sign_in_b(tok2)

            async with plant.a.session() as s:  # A revokes alice's tokens (a bulk update)
                alice = await s.get(User, uid1)
                assert alice is not None
                assert await revoke_tokens(s, alice) == 1
            assert await plant.gone_from_b(k1, 2.0), "a revoked token still signs in on B"
            assert plant.cache_b.get(k2) is not None  # bob's entry is not touched

            async with plant.a.session() as s:  # A disables bob (as the users' route does)
                bob = await s.scalar(select(User).where(User.id == uid2))
                assert bob is not None
                bob.disabled = True
                await users_changed(s, {uid2})
            assert await plant.gone_from_b(k2, 2.0), "a disabled user still signs in on B"
            assert sync.stats.notifications >= 2 and sync.stats.dropped == 2, sync.stats

            # a rolled-back revocation notifies nobody (NOTIFY is sent only on commit)
            _, tok3 = await plant.add_user("carol")
            k3 = await plant.sign_in_b(tok3)
            before = sync.stats.notifications
            with pytest.raises(RuntimeError):
                async with plant.a.session() as s:
                    carol = await s.scalar(select(User).where(User.name == "carol"))
                    assert carol is not None
                    await revoke_tokens(s, carol)
                    raise RuntimeError("the unit of work fails")
            await asyncio.sleep(0.3)
            assert sync.stats.notifications == before
            assert plant.cache_b.get(k3) is not None
        finally:
            await sync.stop()
            await plant.close()

    asyncio.run(main())


def test_without_a_listener_the_ttl_is_the_fallback(postgres_url):
    from tests.utils.clock import SteppedClock

    clock = SteppedClock()

    async def main() -> None:
        plant = Plant(postgres_url, clock)  # the default TTL, on the test's clock
        try:
            uid, tok = await plant.add_user("dave")
            key = await plant.sign_in_b(tok)
            async with plant.a.session() as s:
                dave = await s.get(User, uid)
                assert dave is not None
                await revoke_tokens(s, dave)
            assert plant.cache_b.get(key) is not None  # nobody told B: still cached
            clock.advance(plant.cache_b.ttl_s)
            assert plant.cache_b.get(key) is None  # until the entry's TTL ran out
        finally:
            await plant.close()

    asyncio.run(main())


def test_payloads_name_users_or_everyone():
    assert parse_payload("pid=1;users=3,1") == frozenset({1, 3})
    assert parse_payload("pid=1;users=*") is None
    assert parse_payload("pid=1;users=1,x") is None  # unreadable: forget all
    assert parse_payload("garbage") is None


def test_the_notification_lists_the_users_or_everyone(postgres_url):
    """What :func:`users_changed` sends, as a listener reads it."""

    async def main() -> list[frozenset[int] | None]:
        import asyncpg

        from backend.caches import AUTH_CHANNEL

        heard: asyncio.Queue[str] = asyncio.Queue()
        db = Database(postgres_url)
        u = db.engine.url
        conn = await asyncpg.connect(
            host=u.host, port=u.port, user=u.username, password=u.password, database=u.database
        )
        await conn.add_listener(AUTH_CHANNEL, lambda *a: heard.put_nowait(a[-1]))
        try:
            for ids in ({3, 1}, None, set(range(10_000))):
                async with db.session() as s:
                    await users_changed(s, ids)
            return [parse_payload(await asyncio.wait_for(heard.get(), 10)) for _ in range(3)]
        finally:
            await conn.close()
            await db.dispose()

    assert asyncio.run(main()) == [frozenset({1, 3}), None, None]
