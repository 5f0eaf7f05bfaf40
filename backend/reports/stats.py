"""Order statistics in SQL that give the same answer on SQLite and PostgreSQL.

Percentiles are *nearest-rank* (Hyndman & Fan 1996, definition 1; the classic definition of
NIST's "Engineering Statistics Handbook" 7.2.6.2): the p-th percentile of n values is the
value of rank ``ceil(p n / 100)`` in ascending order, so it is always one of the stored values
(no interpolation, no floating-point arithmetic in the database).  Both engines compute the
ranks with the same window functions (``ROW_NUMBER() OVER (PARTITION BY k ORDER BY v)``,
``COUNT(*) OVER (PARTITION BY k)``) and the same integer arithmetic, and only the rows at
the wanted ranks leave the database.

:func:`percentiles_by_offset` gives the same values without window functions: a count, then
``ORDER BY v LIMIT 1 OFFSET rank - 1`` per percentile, which an index on ``v`` (or on
``(group, v)``) answers by walking the index instead of sorting; SQLite's window functions
materialise and sort every row, which is several times slower over 100,000 rows
(``benchmarks/reports.py``).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from sqlalchemy import ColumnElement, Subquery, func, literal, or_, select
from sqlalchemy.ext.asyncio import AsyncSession

__all__ = ["nearest_rank", "percentiles", "percentiles_by_offset", "ranked"]


def nearest_rank(p: int, n: int) -> int:
    """1-based rank of the ``p``-th percentile (integer percent, 1..100) among ``n`` values."""
    if not 1 <= p <= 100 or n < 1:
        raise ValueError(f"need 1 <= p <= 100 and n >= 1, got p={p!r}, n={n!r}")
    return (p * n + 99) // 100


def ranked(value: ColumnElement[Any], key: ColumnElement[Any] | None, conds: Sequence[Any],
           source: Any = None) -> Subquery:  # fmt: skip
    """A subquery ``(k, v, rn, n)``: ``value`` ranked within each ``key`` (one group if None).

    ``source`` is the FROM (a table or subquery) when ``value``/``key`` are not columns of a
    table already in the conditions.
    """
    k = literal(0) if key is None else key
    q = select(
        k.label("k"),
        value.label("v"),
        func.row_number().over(partition_by=k, order_by=value).label("rn"),
        func.count().over(partition_by=k).label("n"),
    )
    if source is not None:
        q = q.select_from(source)
    return q.where(value.is_not(None), *conds).subquery("ranked")


async def percentiles(session: AsyncSession, sub: Subquery, ps: Sequence[int]) -> dict[Any, dict[int, float]]:  # fmt: skip
    """``{k: {p: value}}`` of the nearest-rank percentiles ``ps`` in each group of ``sub``
    (from :func:`ranked`); groups without values are absent."""
    want = or_(*[sub.c.rn == (sub.c.n * p + 99) // 100 for p in ps])
    rows = (await session.execute(select(sub.c.k, sub.c.v, sub.c.rn, sub.c.n).where(want))).all()
    at: dict[Any, dict[int, float]] = {}
    for k, v, rn, _ in rows:
        at.setdefault(k, {})[int(rn)] = float(v)
    out: dict[Any, dict[int, float]] = {}
    counts = {k: n for k, _, _, n in rows}
    for k, by_rank in at.items():
        out[k] = {p: by_rank[nearest_rank(p, int(counts[k]))] for p in ps}
    return out


async def percentiles_by_offset(session: AsyncSession, value: ColumnElement[Any], conds: Sequence[Any],
                                ps: Sequence[int], n: int | None = None) -> dict[int, float]:  # fmt: skip
    """``{p: value}``: the nearest-rank percentiles of ``value`` over the rows matching
    ``conds`` (``n``: their number of non-null values, counted when not given)."""
    where = [value.is_not(None), *conds]
    if n is None:
        n = int(await session.scalar(select(func.count(value)).where(*where)) or 0)
    if n == 0:
        return {}
    out: dict[int, float] = {}
    for p in ps:
        k = nearest_rank(p, n) - 1
        v = await session.scalar(select(value).where(*where).order_by(value).limit(1).offset(k))
        if v is None:  # rows deleted between the count and this query
            break
        out[p] = float(v)
    return out
