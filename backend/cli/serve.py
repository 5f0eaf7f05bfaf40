"""``visioncell serve``: migrate, assemble the cell (:class:`~backend.runtime.CellRuntime`) and
serve the console, the REST API and the 3D view until Ctrl-C (or SIGTERM)."""

from __future__ import annotations

import asyncio
import contextlib
import faulthandler
import logging
import signal
import sys
from collections.abc import Iterator
from typing import TYPE_CHECKING, Annotated, NoReturn

import typer

from backend import __version__
from backend.cli.common import err, load_settings, out
from backend.cli.users import bootstrap_user

if TYPE_CHECKING:
    from backend.settings import Settings

__all__ = ["serve"]


def serve(
    http_port: Annotated[int | None, typer.Option(help="Override VISIONCELL_HTTP_PORT")] = None,
    viser_port: Annotated[int | None, typer.Option(help="Override VISIONCELL_VISER_PORT")] = None,
    no_migrate: Annotated[
        bool, typer.Option("--no-migrate", help="Do not apply migrations first")
    ] = False,
) -> None:
    """Migrate the database and run the cell: console, REST API and 3D view."""
    from backend.db.migrate import upgrade

    settings = load_settings(http_port=http_port, viser_port=viser_port)
    logging.basicConfig(
        level=settings.log_level.upper(), format="%(asctime)s %(levelname)s %(name)s: %(message)s"
    )
    from backend.logredact import install_redaction

    install_redaction()
    # A fatal signal in a native thread (a SIGBUS from a database file changed under the
    # driver's memory map, see backend.db.sqlitefiles) ends the process at once: say so,
    # with every thread's stack, on stderr beside the log instead of vanishing silently.
    if not faulthandler.is_enabled():
        faulthandler.enable(file=sys.stderr, all_threads=True)
    if settings.sqlite_path() is not None:
        settings.var_dir.mkdir(parents=True, exist_ok=True)
    if not no_migrate:
        upgrade(settings.database_url)
    base = f"http://{settings.http_host}:{settings.http_port}"
    out.print(
        f"[bold]VisionCell {__version__}[/bold]  cell={settings.cell_name} "
        f"driver={settings.driver} camera={settings.camera}"
    )
    out.print(f"  console   {base}/")
    out.print(f"  REST API  {base}/api   (docs: {base}/docs)")
    out.print(f"  3D view   http://{settings.viser_host}:{settings.viser_port}/")
    if settings.bootstrap_operator and settings.auth_enabled:
        started = asyncio.run(bootstrap_user(settings))
        out.print(f"  {started.role} token (user {started.user!r}, valid until the next start):")
        # On purpose, the one place a token is shown: standard output, never a log record.
        print(f"  {started.token}", flush=True)
        if started.role == "engineer":
            out.print("  (loopback demo: an engineer's; in production or on a network address,")
            out.print("  the start-up token is an operator's)")
    out.print("Press Ctrl-C to stop.")
    sys.stdout.flush()
    from backend.eventloop import run
    from backend.runtime import StartupError

    try:
        run(_serve(settings), choice=settings.event_loop)
    except StartupError as exc:
        err.print(f"[red]error:[/red] {exc}")
        raise typer.Exit(1) from None
    _exit_now(0)


def _exit_now(code: int) -> NoReturn:
    """End the process once the cell has stopped cleanly (database closed, threads joined).

    The interpreter's own finalisation would then only garbage-collect the modules' objects
    (the simulator, the recognition index, the 3D view's scene): seconds on a loaded
    machine, with nothing left to close.  The exit functions still run and the streams are
    flushed; only that collection is skipped, so Ctrl-C ends the process within about a
    second.
    """
    import atexit
    import os

    atexit._run_exitfuncs()
    logging.shutdown()
    for stream in (sys.stdout, sys.stderr):
        with contextlib.suppress(Exception):
            stream.flush()
    os._exit(code)


async def _serve(settings: Settings) -> None:
    """The runtime around uvicorn: the cell starts before the first request and stops after
    the last one."""
    import uvicorn

    from backend.api.limits import uvicorn_options
    from backend.app import create_app
    from backend.runtime import CellRuntime

    class _Server(uvicorn.Server):
        """uvicorn without its own signal handling (which re-raises the signal after
        shutdown, interrupting the runtime's clean-up); :func:`_signals` stops it."""

        @contextlib.contextmanager
        def capture_signals(self) -> Iterator[None]:
            yield

    async with CellRuntime(settings) as rt:
        config = uvicorn.Config(
            create_app(settings, runtime=rt),
            host=settings.http_host,
            port=settings.http_port,
            log_level="warning" if settings.log_level == "info" else settings.log_level,
            timeout_graceful_shutdown=1,
            ws_ping_interval=10,
            **uvicorn_options(ws_compression=settings.ws_compression),  # JSON 400/414
        )
        from backend.logredact import install_redaction

        # uvicorn.Config configured its loggers (their handlers exist now).
        install_redaction("uvicorn", "uvicorn.error", "uvicorn.access")
        server = _Server(config)
        with _signals(server):
            await server.serve()
        if server.started is False:
            raise SystemExit(3)  # uvicorn could not bind (it logged why)


@contextlib.contextmanager
def _signals(server: object) -> Iterator[None]:
    """SIGINT/SIGTERM end the server gracefully; a second SIGINT forces it."""
    loop = asyncio.get_running_loop()

    def stop(sig: int) -> None:
        if getattr(server, "should_exit", False) and sig == signal.SIGINT:
            server.force_exit = True  # type: ignore[attr-defined]
        server.should_exit = True  # type: ignore[attr-defined]

    installed = []
    for sig in (signal.SIGINT, signal.SIGTERM):
        with contextlib.suppress(NotImplementedError, RuntimeError):
            loop.add_signal_handler(sig, stop, sig)
            installed.append(sig)
    try:
        yield
    finally:
        for sig in installed:
            loop.remove_signal_handler(sig)
