"""``visioncell user add``: users and their API tokens."""

from __future__ import annotations

import asyncio
from dataclasses import dataclass
from typing import Annotated

import typer

from backend.cli.common import err, load_settings, out
from backend.settings import Settings

__all__ = [
    "BUILTIN_USERS",
    "StartupToken",
    "bootstrap_operator",
    "bootstrap_user",
    "startup_role",
    "user_app",
]

user_app = typer.Typer(help="Users and API tokens.", no_args_is_help=True)


async def _add_user(
    settings: Settings, name: str, role: str, expires_in_days: float | None = None
) -> str:
    from backend import audit
    from backend.auth import create_user, parse_role, token_expiry
    from backend.db.session import Database

    db = Database(settings.database_url)
    try:
        async with db.session() as session:
            user, token = await create_user(
                session,
                name,
                parse_role(role),
                settings.secret_key.get_secret_value(),
                expires_at=token_expiry(expires_in_days),
            )
            audit.record(
                session,
                actor=audit.CLI,
                kind="user",
                entity_id=user.id,
                action="create",
                old=None,
                new={"name": user.name, "role": user.role, "token_label": "created"},
                reason=None,
            )
        return token
    finally:
        await db.dispose()


@user_app.command("add")
def user_add(
    name: Annotated[str, typer.Argument(help="User name (letters, digits, _ . @ -)")],
    role: Annotated[str, typer.Option(help="viewer, operator or engineer")] = "operator",
    expires_in: Annotated[
        float | None,
        typer.Option(
            "--expires-in", help="Days the token is valid (0 < DAYS <= 3650; default: no expiry)"
        ),
    ] = None,
) -> None:
    """Create a user and print its API token (shown once, alone on the last line)."""
    from backend.auth import token_expiry
    from backend.db.migrate import upgrade

    settings = load_settings()
    try:
        expires_at = token_expiry(expires_in)  # validate before touching the database
    except ValueError as exc:
        err.print(f"[red]error:[/red] --expires-in: {exc}")
        raise typer.Exit(2) from None
    upgrade(settings.database_url)
    try:
        token = asyncio.run(_add_user(settings, name, role, expires_in))
    except ValueError as exc:
        err.print(f"[red]error:[/red] {exc}")
        raise typer.Exit(2) from None
    until = f", valid until {expires_at:%Y-%m-%d %H:%M} UTC" if expires_at else ""
    out.print(f"created user {name!r} with role {role}{until}; its token (shown once):")
    print(token)


#: The built-in users that ``visioncell serve`` issues its start-up token to, by role.
BUILTIN_USERS = {"operator": "operator", "engineer": "engineer"}


@dataclass(frozen=True)
class StartupToken:
    """The token ``visioncell serve`` prints at start-up."""

    user: str
    """The built-in user's name."""
    role: str
    """The role the user holds (the token can do what it allows)."""
    token: str
    """The token itself (shown once, never logged)."""


def startup_role(settings: Settings) -> str:
    """The role of the start-up token: ``engineer`` on a development cell that only listens
    on the loopback interface (the person at that computer is the whole plant: they teach,
    inspect and read the reports with one token), ``operator`` anywhere else (in
    production, or reachable from the network, no privileged token is handed out)."""
    if settings.environment == "development" and settings.loopback_only():
        return "engineer"
    return "operator"


async def bootstrap_operator(settings: Settings) -> str:
    """A fresh start-up token for the built-in 'operator' user (every earlier start-up
    token of a built-in user is revoked)."""
    return (await bootstrap_user(settings, "operator")).token


async def bootstrap_user(settings: Settings, role: str | None = None) -> StartupToken:
    """A fresh start-up token for the built-in user of ``role`` (default:
    :func:`startup_role`); every earlier start-up token of every built-in user is revoked,
    so only the token printed by the last start works."""
    from sqlalchemy import select

    from backend import audit
    from backend.auth import UserExists, create_user, issue_token, parse_role, revoke_tokens
    from backend.db.models import ApiToken, User
    from backend.db.session import Database

    role = startup_role(settings) if role is None else role
    if role not in BUILTIN_USERS:
        raise ValueError(f"the start-up token is an operator's or an engineer's, got {role!r}")
    name = BUILTIN_USERS[role]
    secret = settings.secret_key.get_secret_value()
    db = Database(settings.database_url)

    async def once() -> StartupToken:
        async with db.session() as session:
            builtin = (
                await session.scalars(select(User).where(User.name.in_(BUILTIN_USERS.values())))
            ).all()
            revoked = 0
            for other in builtin:
                revoked += await revoke_tokens(session, other, label="startup")
            user = next((u for u in builtin if u.name == name), None)
            if user is None:
                user, token = await create_user(
                    session, name, parse_role(role), secret, label="startup"
                )
            else:
                token = await issue_token(session, user, secret, label="startup")
            token_id = await session.scalar(
                select(ApiToken.id).where(ApiToken.user_id == user.id).order_by(ApiToken.id.desc())
            )
            if token_id is None:
                raise RuntimeError(f"the start-up token of {user.name!r} was not stored")
            audit.record(
                session,
                actor=audit.SYSTEM,
                kind="token",
                entity_id=int(token_id),
                action="issue",
                old=None,
                new={"user": user.name, "role": user.role, "label": "startup", "revoked": revoked},
                reason=f"start-up token of the built-in {user.name}",
            )
            return StartupToken(user=user.name, role=str(user.role), token=token)

    try:
        try:
            return await once()
        except UserExists:
            # Another cell of the plant, starting at the same moment on the same database,
            # created the user between our check and our insert: it exists now, so the
            # second try takes the other branch.
            return await once()
    finally:
        await db.dispose()
