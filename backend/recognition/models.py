"""Object models in the database: create, read, update, delete (the service behind
``/api/models`` and ``visioncell models``).

An object model is one physical ``part`` on one sitting base (chapter 3.5.3: an object on
another base is another model); ``kind`` says whether recognition needs only the top view
(``2d``) or may visit the side views (``3d``); ``threshold`` overrides the automatic one.
Every change that the live index must know about (a rename, a new part, a deletion) is
applied to it after the database accepted it, so the index never holds what the database
refused.  The checks of a model's fields are in :mod:`backend.recognition.modelfields`,
re-exported here.
"""

from __future__ import annotations

from typing import Any

from sqlalchemy import delete, func, select
from sqlalchemy.exc import IntegrityError
from sqlalchemy.ext.asyncio import AsyncSession

from backend import audit
from backend.db.models import ObjectModel, TrainedView
from backend.db.session import Database, changed
from backend.recognition.modelfields import (
    NAME_PATTERN,
    ModelFields,
    check_geometry,
    check_name,
    check_threshold,
    grasp_of,
    parse_kind,
)
from backend.recognition.public import ModelPublic
from vision.errors import Conflict, InvalidInput, NotFound

__all__ = [
    "MAX_MODELS",
    "NAME_PATTERN",
    "ModelFields",
    "check_geometry",
    "check_name",
    "check_threshold",
    "create_model",
    "delete_model",
    "get_model",
    "get_model_by_name",
    "grasp_of",
    "list_models",
    "model_public",
    "parse_kind",
    "set_measured_geometry",
    "taught_rounds",
    "update_model",
    "view_counts",
]

#: Most models one database holds (a plant's catalogue; the index stays in memory).
MAX_MODELS = 10_000
_FIELDS = ("name", "part", "sitting_base", "kind", "threshold", "description", "height_m",
           "grasp_x_m", "grasp_y_m", "grasp_z_m", "geometry_source")  # fmt: skip


def _audit_value(row: ObjectModel) -> dict[str, Any]:
    """The fields of a model as the audit trail stores them."""
    return {k: getattr(row, k) for k in _FIELDS}


def _record(
    session: AsyncSession,
    by: audit.By | None,
    row: ObjectModel,
    action: str,
    old: ObjectModel | None,
    new: ObjectModel | None,
) -> None:
    """The audit row of a model change, and a threshold row if its threshold changed; the
    change is noted for the caches (:func:`backend.db.session.changed`)."""
    changed(session, "object_models", [row.id])
    by = by or audit.By()
    before = None if old is None else _audit_value(old)
    after = None if new is None else _audit_value(new)
    audit.record(
        session,
        actor=by.actor,
        kind="model",
        entity_id=row.id,
        action=action,
        old=before,
        new=after,
        reason=by.reason,
    )
    t_old = None if before is None else before["threshold"]
    t_new = None if after is None else after["threshold"]
    if t_old != t_new and new is not None:
        audit.record(
            session,
            actor=by.actor,
            kind="threshold",
            entity_id=row.id,
            action="set" if t_new is not None else "clear",
            old={"model": row.name, "threshold": t_old},
            new={"model": row.name, "threshold": t_new},
            reason=by.reason,
        )


async def view_counts(session: AsyncSession, model_ids: list[int]) -> dict[int, dict[int, int]]:
    """``{model_id: {viewpoint: number of trained views}}``."""
    if not model_ids:
        return {}
    rows = await session.execute(
        select(TrainedView.model_id, TrainedView.viewpoint, func.count())
        .where(TrainedView.model_id.in_(model_ids))
        .group_by(TrainedView.model_id, TrainedView.viewpoint)
    )
    out: dict[int, dict[int, int]] = {i: {} for i in model_ids}
    for model_id, viewpoint, n in rows:
        out[int(model_id)][int(viewpoint)] = int(n)
    return out


async def taught_rounds(session: AsyncSession, model_ids: list[int]) -> dict[int, int]:
    """``{model_id: teach rounds}``: the distinct object yaws of each model's top views (a
    round turns the object; its camera rolls share the yaw)."""
    if not model_ids:
        return {}
    rows = await session.execute(
        select(TrainedView.model_id, func.count(func.distinct(TrainedView.yaw_rad)))
        .where(TrainedView.model_id.in_(model_ids), TrainedView.viewpoint == 1)
        .group_by(TrainedView.model_id)
    )
    out = dict.fromkeys(model_ids, 0)
    for model_id, n in rows:
        out[int(model_id)] = int(n)
    return out


def model_public(
    row: ObjectModel, counts: dict[int, int] | None = None, rounds: int = 0
) -> dict[str, Any]:
    """JSON form of a model (:class:`ModelPublic`; ``counts``: trained views per viewpoint;
    ``rounds``: its teach rounds, :func:`taught_rounds`, shown beside the rounds its kind
    needs)."""
    return ModelPublic.of(row, counts, rounds).model_dump(mode="json")


async def list_models(
    session: AsyncSession, *, limit: int = 100, offset: int = 0, part: str | None = None
) -> tuple[list[ObjectModel], int]:
    """Models ordered by name, one page of them, and the total count."""
    if not 1 <= limit <= 1000 or offset < 0:
        raise InvalidInput(f"limit must be in 1..1000 and offset >= 0, got {limit}, {offset}")
    where = [] if part is None else [ObjectModel.part == check_name(part, "part")]
    total = await session.scalar(select(func.count()).select_from(ObjectModel).where(*where))
    rows = await session.scalars(
        select(ObjectModel).where(*where).order_by(ObjectModel.name).limit(limit).offset(offset)
    )
    return list(rows), int(total or 0)


async def get_model(session: AsyncSession, model_id: int) -> ObjectModel:
    """The model with this id, or :class:`NotFound`."""
    row = await session.get(ObjectModel, model_id)
    if row is None:
        raise NotFound(f"no object model with id {model_id}")
    return row


async def get_model_by_name(session: AsyncSession, name: str) -> ObjectModel:
    """The model with this name, or :class:`NotFound`."""
    row = await session.scalar(select(ObjectModel).where(ObjectModel.name == name))
    if row is None:
        raise NotFound(f"no object model named {name!r}")
    return row


async def _check_free_name(session: AsyncSession, name: str, *, not_id: int | None = None) -> None:
    other = await session.scalar(select(ObjectModel.id).where(ObjectModel.name == name))
    if other is not None and other != not_id:
        raise Conflict(f"an object model named {name!r} exists already (id {other})")


async def create_model(
    db: Database, fields: ModelFields, *, by: audit.By | None = None
) -> ObjectModel:
    """Insert a model; ``part`` defaults to the name, ``sitting_base`` to ``"default"``."""
    if fields.name is None or fields.kind is None:
        raise InvalidInput("a new model needs a name and a kind ('2d' or '3d')")
    try:
        async with db.session() as session:
            await _check_free_name(session, fields.name)
            n = await session.scalar(select(func.count()).select_from(ObjectModel))
            if int(n or 0) >= MAX_MODELS:
                raise Conflict(f"the database holds {n} models, the most it may hold")
            row = ObjectModel(
                name=fields.name,
                part=fields.part or fields.name,
                sitting_base=fields.sitting_base or "default",
                kind=fields.kind,
                threshold=fields.threshold,
                description=fields.description or "",
            )
            if fields.height_given or fields.grasp_given:
                _set_geometry(row, fields.height_m, fields.grasp_obj, "entered")
            session.add(row)
            await session.flush()
            _record(session, by, row, "create", None, row)
    except IntegrityError as exc:  # a concurrent insert of the same name
        raise Conflict(f"an object model named {fields.name!r} exists already") from exc
    return row


async def update_model(
    db: Database, model_id: int, fields: ModelFields, *, by: audit.By | None = None
) -> tuple[ObjectModel, ObjectModel]:
    """Apply the given fields; return the row before (detached copy) and after."""
    try:
        async with db.session() as session:
            row = await get_model(session, model_id)
            before = ObjectModel(
                id=row.id,
                name=row.name,
                part=row.part,
                sitting_base=row.sitting_base,
                kind=row.kind,
                threshold=row.threshold,
                description=row.description,
                created_at=row.created_at,
                height_m=row.height_m,
                grasp_x_m=row.grasp_x_m,
                grasp_y_m=row.grasp_y_m,
                grasp_z_m=row.grasp_z_m,
                geometry_source=row.geometry_source,
            )
            if fields.name is not None and fields.name != row.name:
                await _check_free_name(session, fields.name, not_id=row.id)
                row.name = fields.name
            for what in ("part", "sitting_base", "kind", "description"):
                value = getattr(fields, what)
                if value is not None:
                    setattr(row, what, value)
            if fields.threshold_given:
                row.threshold = fields.threshold
            if fields.height_given or fields.grasp_given:
                h, g = check_geometry(
                    fields.height_m if fields.height_given else row.height_m,
                    fields.grasp_obj if fields.grasp_given else grasp_of(row),
                )
                _set_geometry(row, h, g, "entered")
            await session.flush()
            _record(session, by, row, "update", before, row)
    except IntegrityError as exc:
        raise Conflict(f"an object model named {fields.name!r} exists already") from exc
    return before, row


def _set_geometry(row: ObjectModel, height_m: float | None,
                  grasp: tuple[float, float, float] | None, source: str) -> None:  # fmt: skip
    row.height_m = height_m
    row.grasp_x_m, row.grasp_y_m, row.grasp_z_m = grasp if grasp is not None else (None,) * 3
    row.geometry_source = source if height_m is not None or grasp is not None else ""


async def set_measured_geometry(
    db: Database, model_id: int, height_m: float, grasp: tuple[float, float, float] | None
) -> ObjectModel | None:
    """Store the height (and grasp point) measured at teach time, unless an engineer has
    entered them (``geometry_source == "entered"``: an entry beats a measurement only when
    the engineer says so).  Returns the row when it changed, else None."""
    h, g = check_geometry(height_m, grasp)
    async with db.session() as session:
        row = await get_model(session, model_id)
        if row.geometry_source == "entered":
            return None
        before = ObjectModel(id=row.id, name=row.name, part=row.part, sitting_base=row.sitting_base,
                             kind=row.kind, threshold=row.threshold, description=row.description,
                             height_m=row.height_m, grasp_x_m=row.grasp_x_m, grasp_y_m=row.grasp_y_m,
                             grasp_z_m=row.grasp_z_m, geometry_source=row.geometry_source)  # fmt: skip
        _set_geometry(row, h, g, "measured")
        await session.flush()
        _record(session, audit.By(), row, "update", before, row)
    return row


async def delete_model(db: Database, model_id: int, *, by: audit.By | None = None) -> ObjectModel:
    """Delete a model and its trained views (inspections keep their rows, model unset)."""
    async with db.session() as session:
        row = await get_model(session, model_id)
        _record(session, by, row, "delete", row, None)
        # Bulk deletes: the views' images are never loaded just to be removed.
        await session.execute(delete(TrainedView).where(TrainedView.model_id == model_id))
        await session.execute(delete(ObjectModel).where(ObjectModel.id == model_id))
    return row
