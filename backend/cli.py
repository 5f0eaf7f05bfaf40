"""The ``visioncell`` command line: serve the cell, migrate the database, manage users,
calibrate offline (``visioncell calibrate``, in :mod:`backend.cli_calibrate`)."""

from __future__ import annotations

import asyncio
import logging
import sys
from typing import Annotated

import typer
from pydantic import ValidationError
from rich.console import Console

from backend import __version__

# Until this module becomes the ``backend/cli/`` package, let its submodules import.
__path__ = [str(__import__("pathlib").Path(__file__).with_suffix(""))]
from backend.cli.models import register as models_register
from backend.cli_calibrate import calibrate_app
from backend.cli_features import train_pca
from backend.settings import Settings

__all__ = ["app", "main"]

app = typer.Typer(
    name="visioncell",
    help="VisionCell: operator console for a vision-guided robot cell. "
    "Configuration comes from VISIONCELL_* environment variables (see README).",
    no_args_is_help=True,
    add_completion=False,
)
db_app = typer.Typer(help="Database migrations (Alembic).", no_args_is_help=True)
user_app = typer.Typer(help="Users and API tokens.", no_args_is_help=True)
app.add_typer(db_app, name="db")
app.add_typer(user_app, name="user")
app.add_typer(calibrate_app, name="calibrate")
app.command("train-pca")(train_pca)
models_register(app)

out = Console()
err = Console(stderr=True)


def load_settings(**overrides: object) -> Settings:
    """Settings from the environment plus command-line overrides; exits with the reason if invalid."""
    try:
        return Settings(**{k: v for k, v in overrides.items() if v is not None})
    except ValidationError as exc:
        for e in exc.errors():
            where = ".".join(str(p) for p in e["loc"]) or "settings"
            err.print(
                f"[red]error:[/red] {where}: {e['msg'].removeprefix('Value error, ')} (got {e.get('input')!r})"
            )
        raise typer.Exit(2) from None


@app.command()
def version() -> None:
    """Print the VisionCell version."""
    out.print(__version__)


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


async def _add_user(settings: Settings, name: str, role: str) -> str:
    from backend.auth import create_user, parse_role
    from backend.db.session import Database

    db = Database(settings.database_url)
    try:
        async with db.session() as session:
            _, token = await create_user(
                session, name, parse_role(role), settings.secret_key.get_secret_value()
            )
        return token
    finally:
        await db.dispose()


@user_app.command("add")
def user_add(
    name: Annotated[str, typer.Argument(help="User name (letters, digits, _ . @ -)")],
    role: Annotated[str, typer.Option(help="viewer, operator or engineer")] = "operator",
) -> None:
    """Create a user and print its API token (shown once, alone on the last line)."""
    from backend.db.migrate import upgrade

    settings = load_settings()
    upgrade(settings.database_url)
    try:
        token = asyncio.run(_add_user(settings, name, role))
    except ValueError as exc:
        err.print(f"[red]error:[/red] {exc}")
        raise typer.Exit(2) from None
    out.print(f"created user {name!r} with role {role}; its token (shown once):")
    print(token)


async def _bootstrap_operator(settings: Settings) -> str:
    """A fresh start-up token for the built-in 'operator' user (the previous one is revoked)."""
    from sqlalchemy import select

    from backend.auth import create_user, issue_token, revoke_tokens
    from backend.db.models import Role, User
    from backend.db.session import Database

    secret = settings.secret_key.get_secret_value()
    db = Database(settings.database_url)
    try:
        async with db.session() as session:
            user = await session.scalar(select(User).where(User.name == "operator"))
            if user is None:
                _, token = await create_user(
                    session, "operator", Role.operator, secret, label="startup"
                )
            else:
                await revoke_tokens(session, user, label="startup")
                token = await issue_token(session, user, secret, label="startup")
        return token
    finally:
        await db.dispose()


@app.command()
def serve(
    http_port: Annotated[int | None, typer.Option(help="Override VISIONCELL_HTTP_PORT")] = None,
    viser_port: Annotated[int | None, typer.Option(help="Override VISIONCELL_VISER_PORT")] = None,
    no_migrate: Annotated[
        bool, typer.Option("--no-migrate", help="Do not apply migrations first")
    ] = False,
) -> None:
    """Migrate the database and run the cell: console, REST API and 3D view."""
    import uvicorn

    from backend.app import create_app
    from backend.db.migrate import upgrade

    settings = load_settings(http_port=http_port, viser_port=viser_port)
    logging.basicConfig(
        level=settings.log_level.upper(), format="%(asctime)s %(levelname)s %(name)s: %(message)s"
    )
    settings.var_dir.mkdir(parents=True, exist_ok=True)
    if not no_migrate:
        upgrade(settings.database_url)
    base = f"http://{settings.http_host}:{settings.http_port}"
    out.print(
        f"[bold]VisionCell {__version__}[/bold]  driver={settings.driver} camera={settings.camera}"
    )
    out.print(f"  console   {base}/")
    out.print(f"  REST API  {base}/api   (docs: {base}/docs)")
    out.print(f"  3D view   http://{settings.viser_host}:{settings.viser_port}/")
    if settings.bootstrap_operator and settings.auth_enabled:
        token = asyncio.run(_bootstrap_operator(settings))
        out.print("  operator token (valid until the next start):")
        print(f"  {token}", flush=True)
    out.print("Press Ctrl-C to stop.")
    sys.stdout.flush()
    uvicorn.run(
        create_app(settings),
        host=settings.http_host,
        port=settings.http_port,
        log_level="warning" if settings.log_level == "info" else settings.log_level,
        timeout_graceful_shutdown=1,
        ws_ping_interval=10,
    )


@app.command()
def emulator(
    driver: Annotated[
        str, typer.Option(help="Arm behind the emulated controller: ideal or sim")
    ] = "ideal",
    link: Annotated[
        str | None, typer.Option(help="Stable device path to create, e.g. var/robot-tty")
    ] = None,
    rate: Annotated[float, typer.Option(help="State events per second")] = 50.0,
    baud: Annotated[
        int | None, typer.Option(help="Pace bytes as a real line at this baud rate")
    ] = None,
    seed: Annotated[int | None, typer.Option(help="Seed of the fault injector")] = None,
    fault_drop: Annotated[float, typer.Option(help="Probability of dropping a frame")] = 0.0,
    fault_corrupt: Annotated[
        float, typer.Option(help="Probability of corrupting a byte of a frame")
    ] = 0.0,
    fault_truncate: Annotated[
        float, typer.Option(help="Probability of cutting a frame short")
    ] = 0.0,
    fault_garbage: Annotated[
        float, typer.Option(help="Probability of a burst of garbage bytes")
    ] = 0.0,
    fault_delay: Annotated[float, typer.Option(help="Probability of delaying a reply")] = 0.0,
    fault_delay_s: Annotated[float, typer.Option(help="Length of an injected delay, s")] = 0.05,
    fault_vanish: Annotated[
        float, typer.Option(help="Probability per frame that the port vanishes")
    ] = 0.0,
    fault_vanish_s: Annotated[
        float, typer.Option(help="How long a vanished port stays away, s")
    ] = 0.5,
) -> None:
    """Emulate the robot controller on a pseudo-terminal; prints the device path first.

    Point a cell at it with VISIONCELL_DRIVER=serial VISIONCELL_SERIAL_PORT=PATH.
    """
    import signal

    from backend.hardware import make_driver
    from robot.drivers.emulator import run_emulator
    from robot.drivers.serial.faults import FaultConfig

    if driver not in ("ideal", "sim"):
        err.print(f"[red]error:[/red] --driver must be 'ideal' or 'sim', got {driver!r}")
        raise typer.Exit(2)
    settings = load_settings(driver=driver)
    try:
        fault = FaultConfig(
            drop_p=fault_drop,
            corrupt_p=fault_corrupt,
            truncate_p=fault_truncate,
            garbage_p=fault_garbage,
            delay_p=fault_delay,
            delay_s=fault_delay_s,
            vanish_p=fault_vanish,
            vanish_s=fault_vanish_s,
        )
    except ValueError as exc:
        err.print(f"[red]error:[/red] {exc}")
        raise typer.Exit(2) from None

    async def run() -> None:
        stop = asyncio.Event()
        loop = asyncio.get_running_loop()
        for sig in (signal.SIGINT, signal.SIGTERM):
            loop.add_signal_handler(sig, stop.set)
        await run_emulator(
            make_driver(settings),
            link=link,
            rate_hz=rate,
            baud=baud,
            fault=fault,
            seed=seed,
            announce=lambda path: print(path, flush=True),
            stop=stop,
        )

    asyncio.run(run())


def main() -> None:
    """Entry point of the ``visioncell`` console script."""
    app()


if __name__ == "__main__":
    main()
