"""``visioncell user add``: users and their API tokens."""

from __future__ import annotations

import asyncio
from typing import Annotated

import typer

from backend.cli.common import err, load_settings, out
from backend.settings import Settings

__all__ = ["bootstrap_operator", "user_app"]

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


async def bootstrap_operator(settings: Settings) -> str:
    """A fresh start-up token for the built-in 'operator' user (the previous one is revoked)."""
    from sqlalchemy import select

    from backend import audit
    from backend.auth import UserExists, create_user, issue_token, revoke_tokens
    from backend.db.models import ApiToken, Role, User
    from backend.db.session import Database

    secret = settings.secret_key.get_secret_value()
    db = Database(settings.database_url)

    async def once() -> str:
        async with db.session() as session:
            user = await session.scalar(select(User).where(User.name == "operator"))
            revoked = 0
            if user is None:
                user, token = await create_user(
                    session, "operator", Role.operator, secret, label="startup"
                )
            else:
                revoked = await revoke_tokens(session, user, label="startup")
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
                reason="start-up token of the built-in operator",
            )
        return token

    try:
        try:
            return await once()
        except UserExists:
            # Another cell of the plant, starting at the same moment on the same database,
            # created the operator between our check and our insert: it exists now, so the
            # second try takes the other branch.
            return await once()
    finally:
        await db.dispose()
