"""What the ``visioncell calibrate`` commands share: their consoles, the ``--json`` and
``--save`` options, errors, the progress bar and the result's output.
"""

from __future__ import annotations

import json
import sys
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Annotated, Any

import typer
from rich.console import Console
from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

__all__ = ["JsonOpt", "SaveOpt", "err", "out"]

out = Console(soft_wrap=True)
err = Console(stderr=True, soft_wrap=True)

JsonOpt = Annotated[
    bool, typer.Option("--json", help="Print one JSON object (the full result) on the last line")
]
SaveOpt = Annotated[
    Path | None, typer.Option("--save", help="Write the result as JSON to this file")
]


def _fail(message: str) -> typer.Exit:
    err.print(f"[red]error:[/red] {message}")
    return typer.Exit(2)


@contextmanager
def _progress(enabled: bool) -> Iterator[Callable[[float, str], None]]:
    if not enabled:
        yield lambda f, m: None
        return
    with Progress(
        TextColumn("{task.description}"),
        BarColumn(),
        TextColumn("{task.percentage:>3.0f}%"),
        TimeElapsedColumn(),
        console=err,
        transient=True,
    ) as bar:
        task = bar.add_task("calibrating", total=1.0)

        def update(f: float, msg: str) -> None:
            bar.update(task, completed=f, description=msg[:60])

        yield update


def _finish(result: dict[str, Any], as_json: bool, save: Path | None) -> None:
    if save is not None:
        save.write_text(json.dumps(result, indent=1))
        err.print(f"saved {save}")
    if as_json:
        sys.stdout.write(json.dumps(result) + "\n")
        sys.stdout.flush()
