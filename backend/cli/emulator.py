"""``visioncell emulator``: the robot controller emulated on a pseudo-terminal."""

from __future__ import annotations

import asyncio
from typing import Annotated

import typer

from backend.cli.common import err, load_settings

__all__ = ["emulator"]


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
    from robot.drivers.emulator import run_emulator  # imported on use: the module may move
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
