"""The ``visioncell`` command line, one module per command group: ``serve``
(:mod:`backend.cli.serve`), ``db`` (:mod:`backend.cli.db`), ``user``
(:mod:`backend.cli.users`), ``calibrate`` (:mod:`backend.cli.calibrate`, with ``auto``
in :mod:`backend.cli.calibration_auto`, ``export`` and ``import`` in
:mod:`backend.cli.calibration_io`), ``train-pca``
(:mod:`backend.cli.features`), ``emulator`` (:mod:`backend.cli.emulator`), ``estop``
(:mod:`backend.cli.estop`), ``models`` (:mod:`backend.cli.models`), ``inspect``
(:mod:`backend.cli.inspect`), ``recipes`` (:mod:`backend.cli.recipes`), ``report``
(:mod:`backend.cli.report`) and ``recognise`` (:mod:`backend.cli.recognise`)."""

from __future__ import annotations

import typer

from backend import __version__
from backend.cli.calibrate import calibrate_app
from backend.cli.calibration_auto import register as register_calibration_auto
from backend.cli.calibration_io import register as register_calibration_io
from backend.cli.common import err, load_settings, out
from backend.cli.db import db_app
from backend.cli.emulator import emulator
from backend.cli.estop import estop
from backend.cli.features import train_pca
from backend.cli.inspect import register as register_inspect
from backend.cli.models import register as register_models
from backend.cli.recipes import register as register_recipes
from backend.cli.recognise import register as register_recognise
from backend.cli.report import register as register_report
from backend.cli.serve import serve
from backend.cli.users import user_app

__all__ = ["app", "err", "load_settings", "main", "out"]

app = typer.Typer(
    name="visioncell",
    help="VisionCell: operator console for a vision-guided robot cell. "
    "Configuration comes from VISIONCELL_* environment variables (see README).",
    no_args_is_help=True,
    add_completion=False,
)
app.add_typer(db_app, name="db")
app.add_typer(user_app, name="user")
app.add_typer(calibrate_app, name="calibrate")
register_calibration_auto(calibrate_app)
register_calibration_io(calibrate_app)
app.command("train-pca")(train_pca)
register_models(app)
register_inspect(app)
register_recipes(app)
register_report(app)
register_recognise(app)


@app.command()
def version() -> None:
    """Print the VisionCell version."""
    out.print(__version__)


app.command()(serve)
app.command()(emulator)
app.command()(estop)


def main() -> None:
    """Entry point of the ``visioncell`` console script."""
    app()
