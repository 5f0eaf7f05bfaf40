"""``visioncell calibrate export ID`` and ``visioncell calibrate import FILE``: calibration
documents through the running cell's REST API (``--url``, ``--token``).

Export needs a viewer token, import an engineer token.  A document is checked here, with
the cell's own rules (:func:`backend.calibration.transfer.check_document`), before any
request: a bad value exits with status 2 and a message naming it.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Annotated, Any

import typer

from backend.cli.remote import cell_api, fail, request

__all__ = ["MAX_DOCUMENT_BYTES", "register"]

#: Largest document file read, bytes (a document takes about 1 KB).
MAX_DOCUMENT_BYTES = 1 << 20
#: Largest calibration id (the database's signed 64-bit integer).
MAX_ID = 2**63 - 1

UrlOpt = Annotated[str | None, typer.Option(help="Cell URL (default: from the settings)")]


def register(group: typer.Typer) -> None:
    """Add ``export`` and ``import`` to the ``calibrate`` command group."""
    group.command("export")(export_calibration)
    group.command("import")(import_calibration)


def export_calibration(
    calibration_id: Annotated[int, typer.Argument(min=1, max=MAX_ID, help="Calibration id")],
    token: Annotated[str, typer.Option(help="Viewer token", envvar="VISIONCELL_TOKEN")],
    output: Annotated[
        Path | None, typer.Option("--output", "-o", help="Write the document to this file")
    ] = None,
    url: UrlOpt = None,
) -> None:
    """Export a calibration of the cell as a JSON document (standard output or -o FILE)."""
    if output is not None and output.is_dir():
        raise fail(f"--output {str(output)!r} is a folder: name a file")
    base = cell_api(url)
    doc = request(f"{base}/calibration/calibrations/{calibration_id}/export", token)
    text = json.dumps(doc, indent=2) + "\n"
    if output is None:
        typer.echo(text, nl=False)
        return
    try:
        output.write_text(text)
    except OSError as exc:
        raise fail(f"cannot write {str(output)!r}: {exc.strerror or exc}") from None
    typer.echo(f"calibration {calibration_id} ({doc.get('kind')}) written to {output}", err=True)


def _read_document(path: Path) -> dict[str, Any]:
    from backend.calibration.transfer import check_document
    from vision.errors import InvalidInput

    if not path.is_file():
        raise fail(f"FILE {str(path)!r} is not a file")
    if path.stat().st_size > MAX_DOCUMENT_BYTES:
        raise fail(f"FILE {str(path)!r} has more than {MAX_DOCUMENT_BYTES} bytes")
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise fail(f"FILE {str(path)!r} is not a JSON calibration document: {exc}") from None
    try:
        check_document(doc)
    except InvalidInput as exc:
        raise fail(f"{path.name}: {exc}") from None
    return dict(doc)


def import_calibration(
    file: Annotated[Path, typer.Argument(help="A document written by calibrate export")],
    token: Annotated[str, typer.Option(help="Engineer token", envvar="VISIONCELL_TOKEN")],
    activate: Annotated[bool, typer.Option(help="Activate it at once")] = False,
    url: UrlOpt = None,
) -> None:
    """Import a calibration document into the cell (a new calibration, optionally active)."""
    doc = _read_document(file)
    base = cell_api(url)
    answer = request(
        f"{base}/calibration/calibrations/import", token, "POST", {**doc, "activate": activate}
    )
    cal = answer.get("calibration")
    if not isinstance(cal, dict) or "id" not in cal:
        raise fail(f"the cell's answer is not a calibration (fields: {', '.join(sorted(answer))})")
    state = "active" if cal.get("active") else "not active"
    typer.echo(f"imported calibration {cal['id']} ({cal.get('kind')}, {state})")
