"""The report aggregations computed from the raw rows in SQL: summary, time series,
confusion matrix -- the reference the block path (:mod:`backend.reports.queries`) is
tested against and the baseline of ``benchmarks/reports.py``; same answers, same API.

Everything is aggregated in SQL (SQLAlchemy Core); only group results leave the database.
Counts and nearest-rank percentiles (:mod:`backend.reports.stats`) are exact and identical on
SQLite and PostgreSQL.  Means are sums of seconds quantised to 0.1 ms (:data:`QUANTUM`, the
resolution the inspection service stores durations with) as whole numbers, which either
engine adds exactly in any order, divided in Python and rounded to 1e-6; summing the floats
themselves would differ in the last bits between the engines.
"""

from __future__ import annotations

from datetime import UTC, datetime, timedelta
from typing import Any, Literal

from sqlalchemy import ColumnElement, String, case, cast, func, select
from sqlalchemy.ext.asyncio import AsyncSession

from backend.db.models import Decision, Inspection, InspectionStage
from backend.reports.filters import DECISIONS, ReportFilters, conditions
from backend.reports.stages import STAGES
from backend.reports.stats import percentiles, percentiles_by_offset, ranked
from vision.errors import InvalidInput

__all__ = [
    "BUCKETS",
    "HIST_BINS",
    "MAX_BUCKETS",
    "QUANTUM",
    "STAGES",
    "confusion",
    "summary",
    "timeseries",
]

#: Durations are summed as whole multiples of this many seconds (module docstring).
QUANTUM = 1e-4
#: Score histogram bins over [0, 1].
HIST_BINS = 10
BUCKETS: dict[str, timedelta] = {
    "minute": timedelta(minutes=1),
    "hour": timedelta(hours=1),
    "day": timedelta(days=1),
}
#: Most buckets in one time series (minute buckets: about a week).
MAX_BUCKETS = 10_000

_I = Inspection.__table__.c


def _r6(x: float | None) -> float | None:
    return None if x is None else round(float(x), 6)


def _qsum(col: Any) -> Any:
    """Exact sum of ``col`` in units of :data:`QUANTUM` (whole numbers as floats < 2^53)."""
    return func.sum(func.round(col * (1.0 / QUANTUM)))


def _recognized() -> ColumnElement[bool]:
    return _I.decision == Decision.recognized.value


async def summary(session: AsyncSession, f: ReportFilters) -> dict[str, Any]:
    """Totals, yield, cycle-time percentiles, the stage breakdown and the score
    distributions per model of the inspections matching ``f`` (the API's ``summary``)."""
    conds = await conditions(session, f)
    rows = (
        await session.execute(
            select(
                _I.decision,
                func.count(),
                func.min(_I.started_at),
                func.max(_I.started_at),
                func.count(_I.duration_s),
                _qsum(_I.duration_s),
                func.max(_I.duration_s),
                func.sum(func.json_array_length(_I.viewpoints_visited)),
            )
            .where(*conds)
            .group_by(_I.decision)
        )
    ).all()
    by = dict.fromkeys(DECISIONS, 0)
    firsts, lasts, maxes = [], [], []
    n_dur, sum_q, sum_views = 0, 0, 0
    for dec, n, t0, t1, nd, sd, md, sv in rows:
        by[str(dec)] = int(n)
        firsts.append(t0)
        lasts.append(t1)
        n_dur += int(nd)
        sum_q += round(float(sd or 0.0))
        sum_views += int(sv or 0)
        if md is not None:
            maxes.append(float(md))
    count = sum(by.values())

    def _t(values: list[datetime | None], pick: Any) -> str | None:
        vals = [v for v in values if v is not None]
        return pick(vals).isoformat() if vals else None

    cyc = await percentiles_by_offset(session, _I.duration_s, conds, (50, 95, 99), n_dur)
    return {
        "count": count,
        "by_decision": by,
        "yield": None if count == 0 else round(by["recognized"] / count, 6),
        "cycle_s": {
            "p50": cyc.get(50),
            "p95": cyc.get(95),
            "p99": cyc.get(99),
            "mean": _r6(sum_q * QUANTUM / n_dur) if n_dur else None,
            "max": max(maxes) if maxes else None,
        },
        "stages": await _stages(session, f),
        "views_mean": _r6(sum_views / count) if count else None,
        "per_model": await _per_model(session, conds),
        "first": _t(firsts, min),
        "last": _t(lasts, max),
        "filters": f.echo(),
    }


async def _stages(session: AsyncSession, f: ReportFilters) -> dict[str, dict[str, float | None]]:
    st = InspectionStage.__table__
    conds = await conditions(session, f, st)
    agg = (
        await session.execute(
            select(st.c.stage, func.count(), _qsum(st.c.seconds)).where(*conds).group_by(st.c.stage)
        )
    ).all()
    counts = {str(s): int(n) for s, n, _ in agg}
    means = {str(s): round(float(t)) * QUANTUM / int(n) for s, n, t in agg if n}
    out: dict[str, dict[str, float | None]] = {}
    for s in sorted(means, key=lambda s: (STAGES.index(s) if s in STAGES else len(STAGES), s)):
        pct = await percentiles_by_offset(session, st.c.seconds, [*conds, st.c.stage == s],
                                          (50, 95), counts[s])  # fmt: skip
        out[s] = {"mean": _r6(means[s]), "p50": pct.get(50), "p95": pct.get(95)}
    return out


def _bin() -> ColumnElement[int]:
    # Bin i holds [i/10, (i+1)/10); the last one also 1.0.  Comparisons, not CAST/FLOOR,
    # so that both engines put a value on a bin edge into the same bin.
    whens = [(_I.score < (i + 1) / HIST_BINS, i) for i in range(HIST_BINS - 1)]
    return case(*whens, else_=HIST_BINS - 1)


async def _per_model(session: AsyncSession, conds: list[Any]) -> list[dict[str, Any]]:
    mc = [*conds, _I.model_name.is_not(None), _I.score.is_not(None)]
    agg = (
        await session.execute(
            select(_I.model_name, func.count(), func.min(_I.score), func.max(_I.score))
            .where(*mc)
            .group_by(_I.model_name)
        )
    ).all()
    b = _bin().label("bin")
    hist = (
        await session.execute(
            select(_I.model_name, b, func.count()).where(*mc).group_by(_I.model_name, b)
        )
    ).all()
    counts: dict[str, list[int]] = {}
    for m, i, n in hist:
        counts.setdefault(str(m), [0] * HIST_BINS)[int(i)] = int(n)
    pct = {
        m: await percentiles_by_offset(session, _I.score, [*mc, _I.model_name == m], (50, 95), n)
        for m, n, _, _ in agg
    }
    edges = [round(i / HIST_BINS, 6) for i in range(HIST_BINS + 1)]
    return [
        {
            "model": str(m),
            "count": int(n),
            "score": {
                "p50": pct[m].get(50),
                "p95": pct[m].get(95),
                "min": float(lo),
                "max": float(hi),
            },
            "hist": {"edges": edges, "counts": counts.get(str(m), [0] * HIST_BINS)},
        }
        for m, n, lo, hi in sorted(agg, key=lambda r: str(r[0]))
    ]


def _bucket_expr(dialect: str, bucket: str) -> ColumnElement[str]:
    """The bucket's start as ``YYYY-MM-DDTHH:MM:SS`` text (UTC) in either engine's SQL."""
    if dialect == "sqlite":
        fmt = {
            "minute": "%Y-%m-%dT%H:%M:00",
            "hour": "%Y-%m-%dT%H:00:00",
            "day": "%Y-%m-%dT00:00:00",
        }
        return func.strftime(fmt[bucket], _I.started_at)
    if dialect == "postgresql":
        utc = func.timezone("UTC", _I.started_at)
        return func.to_char(func.date_trunc(bucket, utc), 'YYYY-MM-DD"T"HH24:MI:SS')
    raise InvalidInput(f"reports support SQLite and PostgreSQL, not {dialect!r}")


def _floor(t: datetime, bucket: str) -> datetime:
    if bucket == "minute":
        return t.replace(second=0, microsecond=0)
    if bucket == "hour":
        return t.replace(minute=0, second=0, microsecond=0)
    return t.replace(hour=0, minute=0, second=0, microsecond=0)


async def timeseries(session: AsyncSession, f: ReportFilters,
                     bucket: Literal["minute", "hour", "day"] = "hour") -> dict[str, Any]:  # fmt: skip
    """Counts per decision and the median cycle time per time bucket (UTC bucket starts).

    Buckets run from the first to the last one holding an inspection, empty ones included
    with zero counts; more than :data:`MAX_BUCKETS` is refused (narrow ``from``/``to``).
    """
    if bucket not in BUCKETS:
        raise InvalidInput(f"bucket must be one of {', '.join(BUCKETS)}, got {bucket!r}")
    conds = await conditions(session, f)
    t0, t1 = f.start, f.end
    if t0 is None or t1 is None:
        lo, hi = (await session.execute(
            select(func.min(Inspection.started_at), func.max(Inspection.started_at)).where(*conds)
        )).one()  # fmt: skip
        t0, t1 = t0 or lo, t1 or hi
    if t0 is not None and t1 is not None:
        n = (_floor(t1, bucket) - _floor(t0, bucket)) // BUCKETS[bucket] + 1
        if n > MAX_BUCKETS:
            raise InvalidInput(
                f"{n} {bucket} buckets from {t0.isoformat()} to {t1.isoformat()} are more "
                f"than {MAX_BUCKETS}: narrow from/to or use a longer bucket"
            )
    bx = _bucket_expr(session.get_bind().dialect.name, bucket).label("t")
    dec = [func.sum(case((_I.decision == d, 1), else_=0)) for d in DECISIONS]
    rows = (await session.execute(select(bx, func.count(), *dec).where(*conds).group_by(bx))).all()
    p50 = await percentiles(session, ranked(_I.duration_s, bx, conds), (50,))
    by_t = {str(r[0]): r for r in rows}
    data: list[dict[str, Any]] = []
    if by_t:
        first = datetime.fromisoformat(min(by_t)).replace(tzinfo=UTC)
        last = datetime.fromisoformat(max(by_t)).replace(tzinfo=UTC)
        t = first
        while t <= last:
            key = t.replace(tzinfo=None).isoformat()
            r = by_t.get(key)
            data.append({
                "t": t.isoformat(),
                "count": 0 if r is None else int(r[1]),
                **{d: 0 if r is None else int(r[2 + i] or 0) for i, d in enumerate(DECISIONS)},
                "cycle_p50": p50.get(key, {}).get(50),
            })  # fmt: skip
            t += BUCKETS[bucket]
    return {"bucket": bucket, "data": data, "filters": f.echo()}


async def confusion(session: AsyncSession, f: ReportFilters) -> dict[str, Any]:
    """Confusion against the simulator's truth (rows with a truth only): rows are the true
    catalogue names, columns the decided label (the model, or ``unknown``/``failed``)."""
    conds = await conditions(session, f)
    truth = Inspection.truth["name"].as_string().label("truth_name")
    label = case(
        (_recognized(), func.coalesce(_I.model_name, "unknown")),
        else_=cast(_I.decision, String(16)),
    ).label("label")
    rows = (
        await session.execute(
            select(truth, label, func.count())
            .where(*conds, truth.is_not(None))
            .group_by(truth, label)
        )
    ).all()
    truths = sorted({str(t) for t, _, _ in rows})
    models = sorted({str(lb) for _, lb, _ in rows} - {"unknown", "failed"})
    labels = [*models, "unknown", "failed"]
    matrix = [[0] * len(labels) for _ in truths]
    ti = {t: i for i, t in enumerate(truths)}
    li = {lb: i for i, lb in enumerate(labels)}
    total = 0
    for t, lb, n in rows:
        matrix[ti[str(t)]][li[str(lb)]] += int(n)
        total += int(n)
    return {
        "labels": labels,
        "truth": truths,
        "matrix": matrix,
        "count": total,
        "filters": f.echo(),
    }
