"""``visioncell recognise IMAGE|FOLDER...``: recognise images with the running cell.

The images (PNG or JPEG; a folder's own images, not its sub-folders) go to ``POST
/api/recognition/recognise`` of the cell at ``--url`` with ``--token``, a few per request,
with a progress bar on standard error.  The results are printed as a table, as JSON
(``--json``: one object on the last line) or as CSV (``--csv``).  An image the cell refuses
(not an image, too large) is reported on its own row with the reason; the others go on.
"""

from __future__ import annotations

import csv
import io
import json
import math
import sys
import urllib.error
import urllib.request
import uuid
from pathlib import Path
from typing import Annotated, Any

import typer

__all__ = ["collect_images", "recognise", "register"]

SUFFIXES = (".png", ".jpg", ".jpeg")
#: Most images one command takes.
MAX_FILES = 100_000
#: Images per request (the cell's own limit, ``recognise_max_images``, may be lower).
BATCH = 8
CSV_FIELDS = ("name", "decision", "model", "score", "threshold", "best_model", "x_px", "y_px",
              "angle_deg", "scale", "total_ms", "inspection_id", "error")  # fmt: skip


def register(app: typer.Typer) -> None:
    """Add the ``recognise`` command to the ``visioncell`` app."""
    app.command("recognise")(recognise)


def _fail(message: str) -> typer.Exit:
    typer.echo(f"error: {message}", err=True)
    return typer.Exit(2)


def collect_images(paths: list[Path]) -> list[Path]:
    """The image files named, folders expanded to their images in name order.

    Raises ``ValueError`` for a path that does not exist, a file that is not PNG or JPEG by
    its name, a folder without images or more than :data:`MAX_FILES` images.
    """
    out: list[Path] = []
    for p in paths:
        if p.is_dir():
            found = sorted(q for q in p.iterdir() if q.is_file() and q.suffix.lower() in SUFFIXES)
            if not found:
                raise ValueError(f"no PNG or JPEG images in {str(p)!r}")
            out += found
        elif p.is_file():
            if p.suffix.lower() not in SUFFIXES:
                raise ValueError(f"{str(p)!r} is not a .png, .jpg or .jpeg file")
            out.append(p)
        else:
            raise ValueError(f"{str(p)!r} does not exist")
        if len(out) > MAX_FILES:
            raise ValueError(f"more than {MAX_FILES} images given")
    return out


def _multipart(files: list[Path], fields: dict[str, str]) -> tuple[bytes, str]:
    boundary = uuid.uuid4().hex
    buf = io.BytesIO()
    for k, v in fields.items():
        buf.write(f'--{boundary}\r\nContent-Disposition: form-data; name="{k}"\r\n\r\n'.encode())
        buf.write(v.encode() + b"\r\n")
    for f in files:
        kind = "image/png" if f.suffix.lower() == ".png" else "image/jpeg"
        name = f.name.replace('"', "_")
        buf.write(
            f'--{boundary}\r\nContent-Disposition: form-data; name="images"; '
            f'filename="{name}"\r\nContent-Type: {kind}\r\n\r\n'.encode()
        )
        buf.write(f.read_bytes() + b"\r\n")
    buf.write(f"--{boundary}--\r\n".encode())
    return buf.getvalue(), f"multipart/form-data; boundary={boundary}"


class _Refused(Exception):
    """The cell answered 4xx: the detail names the reason."""

    def __init__(self, status: int, detail: str) -> None:
        super().__init__(detail)
        self.status = status
        self.detail = detail


def _post(url: str, token: str, files: list[Path], fields: dict[str, str]) -> dict[str, Any]:
    body, ctype = _multipart(files, fields)
    req = urllib.request.Request(url, data=body, method="POST")
    req.add_header("Authorization", f"Bearer {token}")
    req.add_header("Content-Type", ctype)
    try:
        with urllib.request.urlopen(req, timeout=300) as resp:
            return dict(json.loads(resp.read()))
    except urllib.error.HTTPError as exc:
        try:
            detail = str(json.loads(exc.read()).get("detail", ""))
        except Exception:
            detail = ""
        if 400 <= exc.code < 500:
            raise _Refused(exc.code, detail or f"HTTP {exc.code}") from None
        raise _fail(f"POST {url}: HTTP {exc.code} {detail}") from None
    except urllib.error.URLError as exc:
        raise _fail(f"cannot reach the cell at {url}: {exc.reason}") from None


def _error_row(path: Path, detail: str) -> dict[str, Any]:
    return {"name": path.name, "decision": "error", "model": None, "score": None,
            "threshold": None, "best_model": None, "scores": [], "pose": None,
            "durations": {}, "inspection_id": None, "error": detail}  # fmt: skip


def _send(url: str, token: str, batch: list[Path], fields: dict[str, str]) -> list[dict[str, Any]]:
    """Results of one batch; a refused batch is sent again image by image, so that one bad
    file is reported alone.  Refusals that are not about an image (401, 403) end the run."""
    try:
        return list(_post(url, token, batch, fields)["data"])
    except _Refused as exc:
        if exc.status in (401, 403) or len(batch) == 1:
            if exc.status in (401, 403):
                raise _fail(f"the cell refused: {exc.detail}") from None
            return [_error_row(batch[0], exc.detail)]
    out = []
    for p in batch:
        try:
            out += _post(url, token, [p], fields)["data"]
        except _Refused as exc:
            if exc.status in (401, 403):
                raise _fail(f"the cell refused: {exc.detail}") from None
            out.append(_error_row(p, exc.detail))
    return out


def _csv_row(r: dict[str, Any]) -> dict[str, Any]:
    pose = r.get("pose") or {}
    total = sum((r.get("durations") or {}).values())
    angle = pose.get("angle_rad")
    return {
        "name": r["name"],
        "decision": r["decision"],
        "model": r.get("model") or "",
        "score": "" if r.get("score") is None else f"{r['score']:.4f}",
        "threshold": "" if r.get("threshold") is None else f"{r['threshold']:.4f}",
        "best_model": r.get("best_model") or "",
        "x_px": "" if not pose else f"{pose['x_px']:.1f}",
        "y_px": "" if not pose else f"{pose['y_px']:.1f}",
        "angle_deg": "" if angle is None else f"{math.degrees(angle):.2f}",
        "scale": "" if not pose else f"{pose['scale']:.4f}",
        "total_ms": f"{1e3 * total:.1f}" if r.get("durations") else "",
        "inspection_id": r.get("inspection_id") or "",
        "error": r.get("error") or "",
    }


def recognise(
    paths: Annotated[list[Path], typer.Argument(help="Images and folders of images")],
    token: Annotated[
        str, typer.Option(help="Viewer token (operator with --store)", envvar="VISIONCELL_TOKEN")
    ],
    url: Annotated[str | None, typer.Option(help="Cell URL (default: from the settings)")] = None,
    viewpoint: Annotated[int, typer.Option(min=1, max=3, help="1 top, 2 or 3 sides")] = 1,
    region: Annotated[
        str | None, typer.Option(help="x,y,width,height in pixels to look in")
    ] = None,
    store: Annotated[bool, typer.Option(help="Store each result as an inspection")] = False,
    as_json: Annotated[bool, typer.Option("--json", help="Print JSON (last line)")] = False,
    as_csv: Annotated[bool, typer.Option("--csv", help="Print CSV")] = False,
    batch: Annotated[int, typer.Option(min=1, max=64, help="Images per request")] = BATCH,
) -> None:
    """Recognise images with the running cell: the decision, the model and its score per image."""
    if as_json and as_csv:
        raise _fail("give --json or --csv, not both")
    try:
        files = collect_images(paths)
    except ValueError as exc:
        raise _fail(str(exc)) from None
    if url is None:
        from backend.cli.common import load_settings

        s = load_settings()
        url = f"http://{s.http_host}:{s.http_port}"
    endpoint = url.rstrip("/") + "/api/recognition/recognise"
    fields = {"viewpoint": str(viewpoint), "store": "true" if store else "false"}
    if region:
        fields["region"] = region
    from rich.console import Console
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TimeRemainingColumn

    results: list[dict[str, Any]] = []
    progress = Progress(
        "[progress.description]{task.description}", BarColumn(), MofNCompleteColumn(),
        TimeRemainingColumn(), console=Console(stderr=True), disable=len(files) < 2,
    )  # fmt: skip
    with progress:
        task = progress.add_task("recognising", total=len(files))
        for start in range(0, len(files), batch):
            part = files[start : start + batch]
            results += _send(endpoint, token, part, fields)
            progress.advance(task, len(part))
    counts: dict[str, int] = {}
    for r in results:
        counts[r["decision"]] = counts.get(r["decision"], 0) + 1
    if as_json:
        print(json.dumps({"data": results, "count": len(results), "decisions": counts}))
        return
    if as_csv:
        w = csv.DictWriter(sys.stdout, fieldnames=CSV_FIELDS, lineterminator="\n")
        w.writeheader()
        for r in results:
            w.writerow(_csv_row(r))
        return
    from rich.table import Table

    table = Table("image", "decision", "model", "score", "threshold", "ms")
    for r in results:
        row = _csv_row(r)
        table.add_row(row["name"], row["decision"], row["model"] or row["error"], row["score"],
                      row["threshold"], row["total_ms"])  # fmt: skip
    Console().print(table)
    print(", ".join(f"{v} {k}" for k, v in sorted(counts.items())) + f" of {len(results)} images")
