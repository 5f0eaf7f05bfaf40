"""``visioncell report``: the summary table of the inspections in the configured database,
the CSV export and the plots; ``report storage`` and ``report prune`` for image retention.

Reads the database named by ``VISIONCELL_DATABASE_URL`` directly (like ``visioncell db``), so
it works whether or not the cell runs and covers every cell of a plant database
(``--cell`` narrows it).  Every error names the bad value and exits with status 2.
"""

from __future__ import annotations

import asyncio
from collections.abc import Awaitable, Callable
from pathlib import Path
from typing import Annotated, Any, TypeVar

import typer
from rich.table import Table

from backend.cli.common import err, load_settings, out
from vision.errors import VisionCellError

__all__ = ["register", "report_app"]

T = TypeVar("T")

report_app = typer.Typer(
    help="Reports over the stored inspections: summary, CSV, plots; image storage and pruning.",
    invoke_without_command=True,
)


def register(app: typer.Typer) -> None:
    """Add the ``report`` command group to the ``visioncell`` app."""
    app.add_typer(report_app, name="report")


def _run(work: Callable[[Any], Awaitable[T]]) -> T:
    from backend.db.session import Database

    settings = load_settings()

    async def main() -> T:
        db = Database(settings.database_url)
        try:
            return await work(db)
        finally:
            await db.dispose()

    try:
        return asyncio.run(main())
    except VisionCellError as exc:
        err.print(f"[red]error:[/red] {exc.detail}")
        raise typer.Exit(2) from None


def _f(v: float | None, unit: str = "", digits: int = 3) -> str:
    return "-" if v is None else f"{v:.{digits}f}{unit}"


def _print_summary(s: dict[str, Any]) -> None:
    f = {k: v for k, v in s["filters"].items() if v is not None}
    t = Table(
        title="Inspections" + (f" ({', '.join(f'{k}={v}' for k, v in f.items())})" if f else "")
    )
    t.add_column("measure")
    t.add_column("value", justify="right")
    t.add_row("inspections", str(s["count"]))
    for d, n in s["by_decision"].items():
        t.add_row(f"  {d}", str(n))
    t.add_row("yield", "-" if s["yield"] is None else f"{100 * s['yield']:.1f} %")
    for k in ("p50", "p95", "p99", "mean", "max"):
        t.add_row(f"cycle time {k}", _f(s["cycle_s"][k], " s"))
    t.add_row("viewpoints per inspection", _f(s["views_mean"], "", 2))
    t.add_row("first", s["first"] or "-")
    t.add_row("last", s["last"] or "-")
    out.print(t)
    if s["stages"]:
        st = Table(title="Stages (s)")
        for c in ("stage", "mean", "p50", "p95"):
            st.add_column(c, justify="left" if c == "stage" else "right")
        for name, v in s["stages"].items():
            st.add_row(name, _f(v["mean"]), _f(v["p50"]), _f(v["p95"]))
        out.print(st)
    if s["per_model"]:
        pm = Table(title="Scores per model")
        for c in ("model", "count", "p50", "p95", "min", "max"):
            pm.add_column(c, justify="left" if c == "model" else "right")
        for m in s["per_model"]:
            sc = m["score"]
            pm.add_row(m["model"], str(m["count"]), _f(sc["p50"]), _f(sc["p95"]), _f(sc["min"]),
                       _f(sc["max"]))  # fmt: skip
        out.print(pm)


@report_app.callback()
def report(
    ctx: typer.Context,
    start: Annotated[str | None, typer.Option("--from", help="ISO-8601 start (UTC if no offset)")] = None,
    end: Annotated[str | None, typer.Option("--to", help="ISO-8601 end (UTC if no offset)")] = None,
    cell: Annotated[str | None, typer.Option(help="Cell name (default: every cell)")] = None,
    model: Annotated[str | None, typer.Option(help="Recognised model name")] = None,
    decision: Annotated[str | None, typer.Option(help="recognized, unknown or failed")] = None,
    policy: Annotated[str | None, typer.Option(help="naive, top-only, two-views, best-next")] = None,
    csv_file: Annotated[Path | None, typer.Option("--csv", help="Write every matching inspection as CSV")] = None,
    png: Annotated[Path | None, typer.Option(help="Write the plots (PNG) into this folder")] = None,
    bucket: Annotated[str, typer.Option(help="Throughput plot bucket: minute, hour or day")] = "hour",
) -> None:  # fmt: skip
    """Print the summary of the matching inspections; optionally write the CSV and plots."""
    if ctx.invoked_subcommand is not None:
        return
    from backend.reports import confusion, export_csv, make_filters, summary, timeseries
    from backend.reports.export import check_export
    from backend.reports.queries import BUCKETS

    if bucket not in BUCKETS:
        err.print(f"[red]error:[/red] --bucket must be one of {', '.join(BUCKETS)}, got {bucket!r}")
        raise typer.Exit(2)
    if png is not None and png.exists() and not png.is_dir():
        err.print(f"[red]error:[/red] --png must be a folder, {str(png)!r} is a file")
        raise typer.Exit(2)
    if csv_file is not None and (csv_file.is_dir() or not csv_file.parent.is_dir()):
        err.print(f"[red]error:[/red] --csv must be a file in an existing folder, got {str(csv_file)!r}")  # fmt: skip
        raise typer.Exit(2)

    async def work(db: Any) -> tuple[dict[str, Any], dict[str, Any] | None, dict[str, Any] | None, int]:  # fmt: skip
        try:
            f = make_filters(start=start, end=end, cell=cell, model=model, decision=decision,
                             policy=policy)  # fmt: skip
        except VisionCellError as exc:  # name the option, not the API's parameter
            if exc.detail.split(" ", 1)[0] in ("from", "to", "cell", "model", "decision", "policy"):
                exc.detail = "--" + exc.detail
            raise
        async with db.session() as s:
            summ = await summary(s, f)
            ts = await timeseries(s, f, bucket) if png is not None else None  # type: ignore[arg-type]
            cf = await confusion(s, f) if png is not None else None
        n = 0
        if csv_file is not None:
            n = await check_export(db, f)
            tmp = csv_file.with_name(csv_file.name + ".part")
            with tmp.open("w", encoding="utf-8", newline="") as fh:
                async for chunk in export_csv(db, f):
                    fh.write(chunk)
            tmp.replace(csv_file)  # whole or not at all
        return summ, ts, cf, n

    summ, ts, cf, n = _run(work)
    _print_summary(summ)
    if csv_file is not None:
        out.print(f"wrote {n} inspections to {csv_file}")
    if png is not None and ts is not None and cf is not None:
        from backend.reports.plots import plot_all

        for p in plot_all(summ, ts, cf, png):
            out.print(f"wrote {p}")


@report_app.command("storage")
def storage() -> None:
    """Print the images and 3D scenes stored, their bytes and the retention settings."""
    from backend.reports import storage_used

    settings = load_settings()

    async def work(db: Any) -> dict[str, int]:
        async with db.session() as s:
            return await storage_used(s)

    used = _run(work)
    out.print(
        f"{used['images']} images ({used['image_bytes']} bytes), {used['scenes']} scenes "
        f"({used['scene_bytes']} bytes), {used['bytes']} bytes in all; retention "
        f"{settings.image_retention}, max age {settings.image_max_age_days or '-'} days, "
        f"max {settings.image_max_bytes or '-'} bytes"
    )


@report_app.command("prune")
def prune_cmd(
    older_than_days: Annotated[int | None, typer.Option(help="Delete images of inspections older than this (days)")] = None,
    max_bytes: Annotated[int | None, typer.Option(help="Delete the oldest images beyond this many bytes")] = None,
) -> None:  # fmt: skip
    """Delete stored images and scenes by age and/or total size (default: the settings' limits)."""
    from backend.reports import prune
    from backend.reports.retention import MAX_PRUNE_BYTES, MAX_PRUNE_DAYS

    settings = load_settings()
    if older_than_days is not None and not 0 <= older_than_days <= MAX_PRUNE_DAYS:
        err.print(f"[red]error:[/red] --older-than-days must be in 0..{MAX_PRUNE_DAYS}, got {older_than_days}")  # fmt: skip
        raise typer.Exit(2)
    if max_bytes is not None and not 0 <= max_bytes <= MAX_PRUNE_BYTES:
        err.print(f"[red]error:[/red] --max-bytes must be in 0..{MAX_PRUNE_BYTES}, got {max_bytes}")
        raise typer.Exit(2)
    days = settings.image_max_age_days if older_than_days is None else older_than_days
    cap = settings.image_max_bytes if max_bytes is None else max_bytes
    if days is None and cap is None:
        err.print("[red]error:[/red] nothing to prune by: give --older-than-days or --max-bytes "
                  "(or set VISIONCELL_IMAGE_MAX_AGE_DAYS / VISIONCELL_IMAGE_MAX_BYTES)")  # fmt: skip
        raise typer.Exit(2)

    async def work(db: Any) -> Any:
        return await prune(db, older_than_days=days, max_bytes=cap)

    res = _run(work)
    out.print(f"deleted {res.deleted_images} images and {res.deleted_scenes} scenes, "
              f"freed {res.freed_bytes} bytes")  # fmt: skip
