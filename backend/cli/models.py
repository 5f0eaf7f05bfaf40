"""``visioncell models list | add | teach | import | remove | reextract``: object models
from the command line.

``list``, ``add``, ``import``, ``remove`` and ``reextract`` work on the database of the
settings (``VISIONCELL_DATABASE_URL``) through the same services as the REST API; a cell
that is running rebuilds its index from the database at its next start (``teach`` and
changes made through the REST API update a running cell at once).  ``teach`` needs the
arm, so it asks the running cell (``--url``, ``--token``) to run its teach job and follows
the job's progress.

``import`` reads a folder of PNG or JPEG images.  The viewpoint of each image is in its
name (``top``/``vp1``/``v1`` = 1, ``vp2``/``v2``/``inner`` = 2, ``vp3``/``v3``/``outer`` = 3)
or in a ``manifest.json`` beside them: ``[{"file": "a.png", "viewpoint": 1, "mask":
"a_mask.png", "yaw_rad": 0.0}, ...]``; a file ``NAME_mask.png`` next to ``NAME.png`` is
taken as its mask.
"""

from __future__ import annotations

import asyncio
import math
from pathlib import Path
from typing import Annotated, Any

import typer

from backend.cli.remote import cell_api, follow_job, job_failure, job_of, request
from backend.cli.remote import fail as _fail
from backend.cli.viewfolder import MAX_IMPORT_FILES, parse_viewpoint, read_folder

__all__ = ["models_app", "parse_viewpoint", "read_folder", "register"]

models_app = typer.Typer(help="Object models and their trained views.", no_args_is_help=True)


def register(app: typer.Typer) -> None:
    """Add the ``models`` command group to the ``visioncell`` app."""
    app.add_typer(models_app, name="models")


def _settings() -> Any:
    from backend.cli.common import load_settings

    return load_settings()


def _run(coro_fn: Any) -> Any:
    """Run ``coro_fn(db)`` on the settings' database (migrated first)."""
    from backend.db.migrate import upgrade
    from backend.db.session import Database
    from vision.errors import VisionCellError

    settings = _settings()
    upgrade(settings.database_url)

    async def main() -> Any:
        db = Database(settings.database_url)
        try:
            return await coro_fn(db, settings)
        finally:
            await db.dispose()

    try:
        return asyncio.run(main())
    except VisionCellError as exc:
        raise _fail(exc.detail) from None


@models_app.command("list")
def list_models() -> None:
    """Print every object model with its views."""
    from rich.console import Console
    from rich.table import Table

    from backend.recognition import models as svc

    async def work(db: Any, _: Any) -> list[dict[str, Any]]:
        async with db.session() as session:
            rows, _total = await svc.list_models(session, limit=1000)
            counts = await svc.view_counts(session, [r.id for r in rows])
            return [svc.model_public(r, counts[r.id]) for r in rows]

    models = _run(work)
    table = Table("id", "name", "part", "base", "kind", "threshold", "views (1/2/3)")
    for m in models:
        per = m["views_per_viewpoint"]
        table.add_row(
            str(m["id"]),
            m["name"],
            m["part"],
            m["sitting_base"],
            m["kind"],
            "auto" if m["threshold"] is None else f"{m['threshold']:.3f}",
            f"{m['views']} ({per.get('1', 0)}/{per.get('2', 0)}/{per.get('3', 0)})",
        )
    Console().print(table)
    print(f"{len(models)} models")


@models_app.command("add")
def add_model(
    name: Annotated[str, typer.Argument(help="Model name (letters, digits, _ . -)")],
    kind: Annotated[str, typer.Option(help="2d (top view only) or 3d (side views too)")] = "3d",
    part: Annotated[str | None, typer.Option(help="Physical part (default: the name)")] = None,
    base: Annotated[str, typer.Option(help="Sitting base")] = "default",
    threshold: Annotated[float | None, typer.Option(help="Own threshold in [0, 1]")] = None,
    height_mm: Annotated[
        float | None,
        typer.Option(
            help="Part height above its sitting base, mm, in (0, 500] (default: "
            "measured by the teach)"
        ),
    ] = None,
) -> None:
    """Create an object model; prints its id on the last line."""
    from backend import audit
    from backend.recognition import models as svc

    if height_mm is not None and not (math.isfinite(height_mm) and 0.0 < height_mm <= 500.0):
        raise _fail(f"--height-mm must be in (0, 500] mm, got {height_mm!r}")
    try:
        fields = svc.ModelFields(
            name=name, part=part, sitting_base=base, kind=svc.parse_kind(kind), threshold=threshold,
            height_m=None if height_mm is None else height_mm / 1000.0,
            height_given=height_mm is not None,
        )  # fmt: skip
    except ValueError as exc:
        raise _fail(str(exc)) from None

    async def work(db: Any, _: Any) -> Any:
        return await svc.create_model(db, fields, by=audit.By(audit.CLI))

    row = _run(work)
    print(f"created model {row.name!r} ({row.kind.value}, part {row.part!r})")
    print(row.id)


@models_app.command("remove")
def remove_model(name: Annotated[str, typer.Argument(help="Model name")]) -> None:
    """Delete a model and its trained views."""
    from backend import audit
    from backend.recognition import models as svc

    async def work(db: Any, _: Any) -> int:
        async with db.session() as session:
            row = await svc.get_model_by_name(session, name)
        await svc.delete_model(db, row.id, by=audit.By(audit.CLI))
        return row.id

    model_id = _run(work)
    print(f"removed model {name!r} (id {model_id}) and its views")


@models_app.command("import")
def import_views(
    name: Annotated[str, typer.Argument(help="Model name (created as --kind if missing)")],
    folder: Annotated[Path, typer.Argument(help="Folder of images (see `--help` of models)")],
    kind: Annotated[str, typer.Option(help="Kind of a model created by the import")] = "3d",
    replace: Annotated[bool, typer.Option(help="Replace the model's earlier views")] = False,
) -> None:
    """Add trained views from a folder of images (teaching without a robot)."""
    from backend import audit
    from backend.recognition import images as im
    from backend.recognition import models as svc
    from backend.recognition.index import LiveIndex
    from backend.recognition.views import ViewInput, add_views
    from vision.errors import NotFound

    try:
        entries = read_folder(folder)
    except ValueError as exc:
        raise _fail(str(exc)) from None
    if len(entries) > MAX_IMPORT_FILES:
        raise _fail(f"{len(entries)} images in {str(folder)!r}; at most {MAX_IMPORT_FILES}")
    inputs = []
    try:
        for e in entries:
            rgb = im.decode_image(e["file"].read_bytes(), name=e["file"].name)
            mask = None
            if e["mask"] is not None:
                mask = im.decode_mask(
                    e["mask"].read_bytes(), shape=rgb.shape[:2], name=e["mask"].name
                )
            inputs.append(
                ViewInput(
                    rgb,
                    e["viewpoint"],
                    mask,
                    yaw_rad=e["yaw_rad"],
                    source="import",
                    name=e["file"].name,
                )
            )
    except ValueError as exc:
        raise _fail(str(exc)) from None

    async def work(db: Any, settings: Any) -> tuple[int, int]:
        async with db.session() as session:
            try:
                model_id = (await svc.get_model_by_name(session, name)).id
            except NotFound:
                model_id = None
        if model_id is None:
            model_id = (
                await svc.create_model(
                    db,
                    svc.ModelFields(name=name, kind=svc.parse_kind(kind)),
                    by=audit.By(audit.CLI),
                )
            ).id
        live = LiveIndex(
            method=settings.recognition_method,
            max_features=settings.recognition_max_features,
            transfer=settings.resolved_camera_transfer(),
        )
        rows = []
        for start in range(0, len(inputs), 72):  # MAX_VIEWS_PER_REQUEST per transaction
            rows += await add_views(
                db,
                live,
                model_id,
                inputs[start : start + 72],
                replace=replace and start == 0,
                by=audit.By(audit.CLI),
            )
        return model_id, len(rows)

    model_id, n = _run(work)
    print(f"imported {n} views into model {name!r} (id {model_id})")


@models_app.command("reextract")
def reextract(
    name: Annotated[str | None, typer.Argument(help="Only this model")] = None,
    all_views: Annotated[bool, typer.Option("--all", help="Every view, not only stale")] = False,
) -> None:
    """Extract features again from the stored images (after a descriptor version change)."""
    from backend import audit
    from backend.recognition import models as svc
    from backend.recognition.index import LiveIndex
    from backend.recognition.views import reextract_views

    async def work(db: Any, settings: Any) -> int:
        model_id = None
        if name is not None:
            async with db.session() as session:
                model_id = (await svc.get_model_by_name(session, name)).id
        live = LiveIndex(
            method=settings.recognition_method,
            max_features=settings.recognition_max_features,
            transfer=settings.resolved_camera_transfer(),
        )
        await live.load(db)
        return await reextract_views(
            db, live, model_id=model_id, only_stale=not all_views, by=audit.By(audit.CLI)
        )

    print(f"re-extracted {_run(work)} views")


@models_app.command("teach")
def teach(
    name: Annotated[str, typer.Argument(help="Model name")],
    token: Annotated[str, typer.Option(help="Engineer token", envvar="VISIONCELL_TOKEN")],
    url: Annotated[str | None, typer.Option(help="Cell URL (default: from the settings)")] = None,
    background: Annotated[str, typer.Option(help="grab or stored")] = "grab",
    viewpoints: Annotated[str | None, typer.Option(help="e.g. 1,2,3")] = None,
    height: Annotated[float, typer.Option(help="Object height, metres")] = 0.1,
    wait: Annotated[float, typer.Option(help="Longest wait for the object, s")] = 120.0,
    replace: Annotated[bool, typer.Option(help="Replace the model's earlier views")] = False,
    round_: Annotated[
        str | None,
        typer.Option(
            "--round",
            help="K/N: round K of N, the object turned to the K-th of N yaws over the "
            "whole turn ((K-1) * 360 / N deg from its first round's pose); each teach "
            "prints the next round's command",
        ),
    ] = None,
) -> None:
    """Teach a model with the arm of the running cell and follow the job."""
    if background not in ("grab", "stored"):
        raise _fail(f"--background must be 'grab' or 'stored', got {background!r}")
    yaw_rad = 0.0
    last_round = True  # the automatic threshold is chosen at the end of the last round
    if round_ is not None:
        from backend.recognition.teach import MAX_ROUNDS, teach_yaws_rad

        try:
            k, n = (int(v) for v in round_.split("/"))
        except ValueError:
            raise _fail(f"--round must be K/N (e.g. 2/4), got {round_!r}") from None
        if not 1 <= n <= MAX_ROUNDS or not 1 <= k <= n:
            raise _fail(f"--round K/N needs 1 <= K <= N <= {MAX_ROUNDS}, got {round_!r}")
        yaw_rad = teach_yaws_rad(n)[k - 1]
        last_round = k == n
        print(f"round {k}/{n}: the object turned by {math.degrees(yaw_rad):.1f} deg "
              "from its first round's pose", flush=True)  # fmt: skip
    vps = None
    if viewpoints is not None:
        try:
            vps = [int(v) for v in viewpoints.split(",")]
        except ValueError:
            raise _fail(f"--viewpoints must be like 1,2,3, got {viewpoints!r}") from None
    base = cell_api(url)
    found = request(f"{base}/models?limit=1000", token)
    model = next((m for m in found["data"] if m["name"] == name), None)
    if model is None:
        raise _fail(f"no object model named {name!r} at {base.removesuffix('/api')}")
    body: dict[str, Any] = {
        "background": background,
        "object_height_m": height,
        "wait_s": wait,
        "replace": replace,
        "yaw_rad": yaw_rad,
        "threshold": last_round,
    }
    if vps is not None:
        body["viewpoints"] = vps
    job = job_of(request(f"{base}/models/{model['id']}/teach", token, "POST", body))
    job = follow_job(base, token, job)
    if job["state"] != "done":
        raise job_failure(job, "teach")
    res = job["result"]
    print(f"taught {len(res['views'])} views of {name!r}; threshold: {res['threshold']['reason']}")
    for why in res.get("left_out") or ():
        print(f"left out: {why}")
    guide = res.get("rounds") or {}
    if guide.get("next_round"):
        k, n = guide["next_round"], guide["recommended"]
        print(f"round {guide['taught']} of the {n} a {model['kind']} model needs to be recognised "
              f"at any yaw; next: turn the object to {guide['next_yaw_deg']:g} deg from its "
              f"first round's pose, keep it at the station, and run\n"
              f"  visioncell models teach {name} --round {k}/{n} --background stored "
              "--token TOKEN",
              flush=True)  # fmt: skip
    elif guide:
        n = guide["recommended"]
        which = "the one round" if n == 1 else f"all {n} rounds"
        print(f"{which} a {model['kind']} model needs {'is' if n == 1 else 'are'} taught: it is "
              "recognised at any yaw", flush=True)  # fmt: skip
    for p in res["confusable_from_top"]:
        print(f"  alike from the top: {p['model']} ~ {p['confused_with']} ({p['rate']:.0%})")
