"""What every command group of the ``visioncell`` CLI shares: consoles and the settings."""

from __future__ import annotations

from typing import Any

import typer
from pydantic import ValidationError
from rich.console import Console

from backend.settings import Settings

__all__ = ["err", "load_settings", "out"]

out = Console()
err = Console(stderr=True)


def load_settings(**overrides: object) -> Settings:
    """Settings from the environment plus command-line overrides; exits with the reason if invalid."""
    try:
        # Settings validates every value (a bad one is reported below), so any type goes in.
        given: dict[str, Any] = {k: v for k, v in overrides.items() if v is not None}
        return Settings(**given)
    except ValidationError as exc:
        for e in exc.errors():
            where = ".".join(str(p) for p in e["loc"]) or "settings"
            err.print(
                f"[red]error:[/red] {where}: {e['msg'].removeprefix('Value error, ')} (got {e.get('input')!r})"
            )
        raise typer.Exit(2) from None
