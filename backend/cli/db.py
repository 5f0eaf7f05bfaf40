"""``visioncell db upgrade|downgrade``: Alembic migrations of the configured database."""

from __future__ import annotations

from typing import Annotated

import typer

from backend.cli.common import load_settings, out

__all__ = ["db_app"]

db_app = typer.Typer(help="Database migrations (Alembic).", no_args_is_help=True)


@db_app.command("upgrade")
def db_upgrade(revision: Annotated[str, typer.Argument(help="Target revision")] = "head") -> None:
    """Apply migrations up to REVISION (default: the newest)."""
    from backend.db.migrate import upgrade

    settings = load_settings()
    upgrade(settings.database_url, revision)
    out.print(f"database {settings.redacted_database_url()} upgraded to {revision}")


@db_app.command("downgrade")
def db_downgrade(
    revision: Annotated[
        str, typer.Argument(help="Target revision ('base' removes every table)")
    ] = "-1",
) -> None:
    """Revert migrations down to REVISION (default: one step)."""
    from backend.db.migrate import downgrade

    settings = load_settings()
    downgrade(settings.database_url, revision)
    out.print(f"database {settings.redacted_database_url()} downgraded to {revision}")
