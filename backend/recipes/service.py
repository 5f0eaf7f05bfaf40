"""Recipes in the database: list, create, change, delete, and the one active per cell.

Every change (and every selection) is audited (:mod:`backend.audit`) in its own
transaction.  Engineers create, change and delete recipes; operators and the PLC links
select one (a line changeover).  Inspections and runs started without a recipe of their
own take the active one (:func:`resolve_options`); a run reads it again before each object
(:func:`follower`), so a recipe selected between two objects applies to the next one.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from sqlalchemy import func, select
from sqlalchemy.exc import IntegrityError
from sqlalchemy.ext.asyncio import AsyncSession

from backend import audit
from backend.db.models import ObjectModel, RecipeSelection
from backend.db.models import Recipe as RecipeRow
from backend.db.types import utcnow
from backend.inspection.options import InspectOptions, Resolve
from backend.recipes.model import (
    MAX_DESCRIPTION,
    MAX_RECIPES,
    Recipe,
    RecipeOptions,
    check_bins,
    check_models,
    check_name,
    check_number,
    options_for,
)
from vision.errors import Conflict, InvalidInput, NotFound

__all__ = ["RecipeFields", "activate", "activate_number", "active_recipe", "create_recipe",
           "delete_recipe", "follower", "get_recipe", "list_recipes", "options_for",
           "resolve_options", "update_recipe"]  # fmt: skip


@dataclass(frozen=True)
class RecipeFields:
    """A recipe's fields as a request gives them (None: not given; a change keeps it)."""

    name: str | None = None
    number: int | None = None
    description: str | None = None
    options: Mapping[str, Any] | None = None
    models: list[str] | tuple[str, ...] | None = None
    bins: Mapping[str, str] | None = None


def _recipe(row: RecipeRow, active_id: int | None) -> Recipe:
    return Recipe(
        id=int(row.id), name=row.name, number=int(row.number),
        options=RecipeOptions.from_dict(row.options or {}),
        models=tuple(str(m) for m in row.models or ()),
        bins=tuple(sorted((str(m), str(b)) for m, b in (row.bins or {}).items())),
        description=row.description or "", active=row.id == active_id,
        created_at=row.created_at, updated_at=row.updated_at,
    )  # fmt: skip


def _audit_value(r: Recipe) -> dict[str, Any]:
    out = r.public()
    for key in ("created_at", "updated_at", "active"):
        out.pop(key)
    return out


def _actor(actor: str | audit.Actor, role: str) -> audit.Actor:
    if isinstance(actor, audit.Actor):
        return actor
    if not isinstance(actor, str) or not 1 <= len(actor) <= 64:
        raise InvalidInput(f"actor must be a name of 1..64 characters, got {actor!r}"[:200])
    return audit.Actor(actor, role)


async def _active_id(session: AsyncSession, cell_id: int) -> int | None:
    return await session.scalar(
        select(RecipeSelection.recipe_id).where(RecipeSelection.cell_id == cell_id)
    )


async def _row(session: AsyncSession, cell_id: int, recipe_id: int) -> RecipeRow:
    if isinstance(recipe_id, bool) or not isinstance(recipe_id, int) or not 1 <= recipe_id < 2**31:
        raise InvalidInput(f"a recipe id is an integer in 1..{2**31 - 1}, got {recipe_id!r}"[:200])
    row = await session.scalar(
        select(RecipeRow).where(RecipeRow.id == recipe_id, RecipeRow.cell_id == cell_id)
    )
    if row is None:
        raise NotFound(f"no recipe {recipe_id} in this cell")
    return row


async def list_recipes(rt: Any) -> list[Recipe]:
    """The cell's recipes by number."""
    async with rt.database.session() as session:
        active = await _active_id(session, rt.cell_id)
        rows = await session.scalars(
            select(RecipeRow).where(RecipeRow.cell_id == rt.cell_id).order_by(RecipeRow.number)
        )
        return [_recipe(r, active) for r in rows]


async def get_recipe(rt: Any, recipe_id: int) -> Recipe:
    """One recipe of the cell (:class:`NotFound` if it has none of that id)."""
    async with rt.database.session() as session:
        return _recipe(
            await _row(session, rt.cell_id, recipe_id), await _active_id(session, rt.cell_id)
        )


async def active_recipe(rt: Any) -> Recipe | None:
    """The cell's active recipe (None: none selected)."""
    async with rt.database.session() as session:
        active = await _active_id(session, rt.cell_id)
        if active is None:
            return None
        row = await session.get(RecipeRow, active)
        return None if row is None else _recipe(row, active)


async def _check_models(session: AsyncSession, models: tuple[str, ...],
                        bins: tuple[tuple[str, str], ...]) -> None:  # fmt: skip
    names = set(models) | {m for m, _ in bins}
    if not names:
        return
    known = set(await session.scalars(select(ObjectModel.name).where(ObjectModel.name.in_(names))))
    missing = sorted(names - known)
    if missing:
        raise InvalidInput(f"no object model named {', '.join(missing)}"[:300])


def _check_bin_names(rt: Any, bins: tuple[tuple[str, str], ...]) -> None:
    layout = getattr(rt, "layout", None)
    if layout is None or not bins:
        return
    have = {b.name for b in layout.bins}
    missing = sorted({b for _, b in bins} - have)
    if missing:
        raise InvalidInput(
            f"no bin named {', '.join(missing)} in this cell; bins: {', '.join(sorted(have))}"[:400]
        )


def _check_description(text: object) -> str:
    if not isinstance(text, str) or len(text) > MAX_DESCRIPTION:
        raise InvalidInput(f"description must be text of at most {MAX_DESCRIPTION} characters")
    return text


def _integrity(exc: IntegrityError, name: str | None, number: int | None) -> Conflict:
    return Conflict(f"this cell has a recipe named {name!r} or numbered {number} already")


async def create_recipe(rt: Any, fields: RecipeFields, *, by: audit.By) -> Recipe:
    """Insert a recipe (name and number required, unique in the cell); audited."""
    if fields.name is None or fields.number is None:
        raise InvalidInput("a new recipe needs a name and a number")
    name, number = check_name(fields.name), check_number(fields.number)
    options = RecipeOptions.from_dict(_check_options(fields.options or {}))
    models = check_models(fields.models or ())
    bins = check_bins(fields.bins or {}, models)
    description = _check_description(fields.description or "")
    _check_bin_names(rt, bins)
    try:
        async with rt.database.session() as session:
            await _check_models(session, models, bins)
            await _check_free(session, rt.cell_id, name, number)
            n = await session.scalar(
                select(func.count()).select_from(RecipeRow).where(RecipeRow.cell_id == rt.cell_id)
            )
            if int(n or 0) >= MAX_RECIPES:
                raise Conflict(f"this cell holds {n} recipes, the most it may hold")
            now = utcnow()
            row = RecipeRow(cell_id=rt.cell_id, name=name, number=number, description=description,
                            options=options.as_dict(), models=list(models), bins=dict(bins),
                            created_at=now, updated_at=now)  # fmt: skip
            session.add(row)
            await session.flush()
            out = _recipe(row, await _active_id(session, rt.cell_id))
            audit.record(session, actor=by.actor, kind="recipe", entity_id=out.id,
                         action="create", old=None, new=_audit_value(out), reason=by.reason)  # fmt: skip
    except IntegrityError as exc:  # a concurrent insert of the same name or number
        raise _integrity(exc, name, number) from exc
    return out


def _check_options(options: Mapping[str, Any]) -> Mapping[str, Any]:
    if not isinstance(options, Mapping):
        raise InvalidInput("options must be an object")
    known = set(RecipeOptions.__dataclass_fields__)
    bad = sorted(set(options) - known)
    if bad:
        raise InvalidInput(f"unknown recipe options {bad!r}; options are {sorted(known)!r}"[:300])
    return options


async def _check_free(session: AsyncSession, cell_id: int, name: str | None, number: int | None,
                      *, other_than: int | None = None) -> None:  # fmt: skip
    for col, value, what in (
        (RecipeRow.name, name, "named"),
        (RecipeRow.number, number, "numbered"),
    ):
        if value is None:
            continue
        q = select(RecipeRow.id).where(RecipeRow.cell_id == cell_id, col == value)
        if other_than is not None:
            q = q.where(RecipeRow.id != other_than)
        if await session.scalar(q) is not None:
            raise Conflict(f"this cell has a recipe {what} {value!r} already")


async def update_recipe(rt: Any, recipe_id: int, fields: RecipeFields, *, by: audit.By) -> Recipe:
    """Change the given fields (options merge: the keys given replace theirs); audited.
    A run following the recipe takes the change from its next object."""
    name = None if fields.name is None else check_name(fields.name)
    number = None if fields.number is None else check_number(fields.number)
    try:
        async with rt.database.session() as session:
            row = await _row(session, rt.cell_id, recipe_id)
            active = await _active_id(session, rt.cell_id)
            before = _recipe(row, active)
            options = before.options
            if fields.options is not None:
                options = RecipeOptions.from_dict(
                    {**options.as_dict(), **_check_options(fields.options)}
                )
            models = before.models if fields.models is None else check_models(fields.models)
            bins = check_bins(dict(before.bins) if fields.bins is None else fields.bins, models)
            _check_bin_names(rt, bins)
            await _check_models(session, models, bins)
            await _check_free(session, rt.cell_id, name, number, other_than=row.id)
            if name is not None:
                row.name = name
            if number is not None:
                row.number = number
            if fields.description is not None:
                row.description = _check_description(fields.description)
            row.options, row.models, row.bins = options.as_dict(), list(models), dict(bins)
            row.updated_at = utcnow()
            await session.flush()
            after = _recipe(row, active)
            audit.record(session, actor=by.actor, kind="recipe", entity_id=row.id,
                         action="update", old=_audit_value(before), new=_audit_value(after),
                         reason=by.reason)  # fmt: skip
    except IntegrityError as exc:
        raise _integrity(exc, name, number) from exc
    return after


async def delete_recipe(rt: Any, recipe_id: int, *, by: audit.By) -> None:
    """Delete a recipe; :class:`Conflict` while it is the active one (select another
    first: a run or a PLC may be following it).  Inspections keep its id and name."""
    async with rt.database.session() as session:
        row = await _row(session, rt.cell_id, recipe_id)
        active = await _active_id(session, rt.cell_id)
        if row.id == active:
            raise Conflict(f"recipe {row.name!r} is the active one: select another first")
        old = _audit_value(_recipe(row, active))
        await session.delete(row)
        audit.record(session, actor=by.actor, kind="recipe", entity_id=recipe_id,
                     action="delete", old=old, new=None, reason=by.reason)  # fmt: skip


async def _select(rt: Any, session: AsyncSession, row: RecipeRow, actor: audit.Actor,
                  reason: str | None) -> Recipe:  # fmt: skip
    sel = await session.get(RecipeSelection, rt.cell_id)
    old_id = None if sel is None else sel.recipe_id
    old_row = None if old_id is None else await session.get(RecipeRow, old_id)
    if sel is None:
        sel = RecipeSelection(cell_id=rt.cell_id, recipe_id=row.id)
        session.add(sel)
    sel.recipe_id, sel.activated_at, sel.activated_by = row.id, utcnow(), actor.name[:64]
    await session.flush()
    audit.record(
        session, actor=actor, kind="recipe", entity_id=row.id, action="activate",
        old=None if old_row is None else {"active": old_row.id, "name": old_row.name,
                                          "number": old_row.number},
        new={"active": row.id, "name": row.name, "number": row.number}, reason=reason,
    )  # fmt: skip
    return _recipe(row, row.id)


async def activate(rt: Any, recipe_id: int, *, actor: str | audit.Actor, role: str = "system",
                   reason: str | None = None) -> Recipe:  # fmt: skip
    """Make ``recipe_id`` the cell's active recipe; audited (``actor``: a name, recorded
    with ``role``, or an :class:`~backend.audit.Actor`).  :class:`NotFound` for an id the
    cell has not, :class:`InvalidInput` for one that is no id."""
    who = _actor(actor, role)

    async def select_it(session: AsyncSession) -> RecipeRow:
        return await _row(session, rt.cell_id, recipe_id)

    return await _select_retrying(rt, select_it, who, reason)


async def _select_retrying(rt: Any, find: Any, who: audit.Actor, reason: str | None) -> Recipe:
    """:func:`_select` of the row ``find(session)`` gives; once more when a concurrent first
    selection of the cell inserted its row meanwhile (then it is an update)."""
    for attempt in (1, 2):
        try:
            async with rt.database.session() as session:
                return await _select(rt, session, await find(session), who, reason)
        except IntegrityError as exc:
            if attempt == 2:
                raise Conflict("the active recipe changed meanwhile: select again") from exc
    raise AssertionError("unreachable")


async def activate_number(rt: Any, number: int, *, actor: str | audit.Actor,
                          role: str = "system", reason: str | None = None) -> Recipe:  # fmt: skip
    """:func:`activate` by the recipe's number (what a PLC sends)."""
    number = check_number(number)
    who = _actor(actor, role)

    async def by_number(session: AsyncSession) -> RecipeRow:
        row = await session.scalar(
            select(RecipeRow).where(RecipeRow.cell_id == rt.cell_id, RecipeRow.number == number)
        )
        if row is None:
            raise NotFound(f"no recipe numbered {number} in this cell")
        return row

    return await _select_retrying(rt, by_number, who, reason)


async def resolve_options(rt: Any, overrides: Mapping[str, Any], *,
                          recipe_id: int | None = None) -> InspectOptions:  # fmt: skip
    """The options of a request: recipe ``recipe_id`` (None: the active one, if any) with
    the request's explicit ``overrides`` over it."""
    recipe = await (active_recipe(rt) if recipe_id is None else get_recipe(rt, recipe_id))
    return options_for(recipe, overrides)


def follower(rt: Any, overrides: Mapping[str, Any], *, recipe_id: int | None = None) -> Resolve:
    """What a run calls before each object: :func:`resolve_options` now."""
    fixed = dict(overrides)

    async def resolve() -> InspectOptions:
        return await resolve_options(rt, fixed, recipe_id=recipe_id)

    return resolve
