"""The report aggregations: summary, time series, confusion matrix (the API's and the CLI's).

They read the inspections' packed records (:mod:`backend.reports.blocks`: one indexed
query for the blocks of the cell and hours asked for) and aggregate in numpy.  The answers
are exact and the same as the SQL over the raw rows (:mod:`backend.reports.sql`, kept as
the reference and the benchmark's baseline), on SQLite and PostgreSQL alike:

- counts per decision, model, bucket and confusion cell are integer counts;
- percentiles are *nearest-rank* (Hyndman & Fan 1996, definition 1): the p-th percentile of
  n values is the stored value of rank ``ceil(p n / 100)`` (:func:`backend.reports.stats.nearest_rank`),
  never an interpolation or a histogram bin;
- means are sums of seconds quantised to 0.1 ms (:data:`QUANTUM`, the resolution the
  inspection service stores durations with) as whole numbers, divided and rounded to 1e-6.

Cost: linear in the records covered (127 bytes each, 13 MB per 100,000 inspections: read in
30-80 ms, aggregated in 20-100 ms on the shared machine, ``benchmarks/reports.py``), against
one ``ORDER BY .. OFFSET`` walk per percentile, stage and model over up to a million stage
rows and full scans for the totals on the SQL path (seconds).
"""

from __future__ import annotations

from dataclasses import dataclass
from datetime import datetime, timedelta
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray
from sqlalchemy.ext.asyncio import AsyncSession

from backend.reports.blocks import Records, datetime_of, load
from backend.reports.filters import DECISIONS, ReportFilters
from backend.reports.sql import BUCKETS, HIST_BINS, MAX_BUCKETS, QUANTUM, _floor
from backend.reports.stages import STAGES
from backend.reports.stats import nearest_rank
from vision.errors import InvalidInput

__all__ = ["BUCKETS", "HIST_BINS", "MAX_BUCKETS", "STAGES", "confusion", "summary", "timeseries"]

_REC = DECISIONS.index("recognized")


def _r6(x: float | None) -> float | None:
    return None if x is None else round(float(x), 6)


def _pcts(v: NDArray[np.float64], ps: tuple[int, ...]) -> dict[int, float]:
    """Nearest-rank percentiles of the (NaN-free) values ``v``; empty for no values."""
    n = len(v)
    if n == 0:
        return {}
    ks = sorted({nearest_rank(p, n) - 1 for p in ps})
    part = np.partition(v, ks)
    return {p: float(part[nearest_rank(p, n) - 1]) for p in ps}


@dataclass(frozen=True)
class _Stats:
    n: int
    """Values present (not NaN)."""
    pct: dict[int, float]
    """Nearest-rank percentiles."""
    qsum: int
    """Sum in whole units of :data:`QUANTUM`."""
    max: float | None


def _stats(col: NDArray[np.float64], ps: tuple[int, ...]) -> _Stats:
    """Count, percentiles, quantised sum and maximum of the values of ``col`` (a field of
    the records; NaN = no value), with one copy of the column."""
    c = np.asarray(col, dtype=np.float64)
    v = c[~np.isnan(c)]  # an owned copy: partitioned in place below
    n = len(v)
    if n == 0:
        return _Stats(0, {}, 0, None)
    qsum = int(np.rint(v * (1.0 / QUANTUM)).astype(np.int64).sum())
    vmax = float(v.max())
    v.partition(sorted({nearest_rank(p, n) - 1 for p in ps}))
    return _Stats(n, {p: float(v[nearest_rank(p, n) - 1]) for p in ps}, qsum, vmax)


async def summary(session: AsyncSession, f: ReportFilters) -> dict[str, Any]:
    """Totals, yield, cycle-time percentiles, the stage breakdown and the score
    distributions per model of the inspections matching ``f`` (the API's ``summary``)."""
    rs = await load(session, f)
    r = rs.rec
    count = len(r)
    by_dec = np.bincount(r["decision"].astype(np.intp), minlength=len(DECISIONS))
    by = {d: int(by_dec[i]) for i, d in enumerate(DECISIONS)}
    cyc = _stats(r["cycle"], (50, 95, 99))
    stages: dict[str, dict[str, float | None]] = {}
    for s in STAGES:
        st = _stats(r[f"s_{s}"], (50, 95))
        if st.n:
            mean = _r6(st.qsum * QUANTUM / st.n)
            stages[s] = {"mean": mean, "p50": st.pct[50], "p95": st.pct[95]}
    t = r["t_us"]
    return {
        "count": count,
        "by_decision": by,
        "yield": None if count == 0 else round(by["recognized"] / count, 6),
        "cycle_s": {
            "p50": cyc.pct.get(50),
            "p95": cyc.pct.get(95),
            "p99": cyc.pct.get(99),
            "mean": _r6(cyc.qsum * QUANTUM / cyc.n) if cyc.n else None,
            "max": cyc.max,
        },
        "stages": stages,
        "views_mean": _r6(int(r["views"].astype(np.int64).sum()) / count) if count else None,
        "per_model": _per_model(rs),
        "first": datetime_of(int(t.min())).isoformat() if count else None,
        "last": datetime_of(int(t.max())).isoformat() if count else None,
        "filters": f.echo(),
    }


def _per_model(rs: Records) -> list[dict[str, Any]]:
    r = rs.rec
    sc = np.ascontiguousarray(r["score"])
    has = (r["model"] >= 0) & ~np.isnan(sc)
    models, scores = r["model"][has], sc[has]
    # Bin i holds [i/10, (i+1)/10); the last one also 1.0 (the SQL path's comparisons).
    inner = np.array([(i + 1) / HIST_BINS for i in range(HIST_BINS - 1)])
    edges = [round(i / HIST_BINS, 6) for i in range(HIST_BINS + 1)]
    out = []
    for mid in np.unique(models):
        v = scores[models == mid]
        p = _pcts(v, (50, 95))
        counts = np.bincount(np.searchsorted(inner, v, side="right"), minlength=HIST_BINS)
        out.append({
            "model": rs.names[int(mid)],
            "count": len(v),
            "score": {"p50": p[50], "p95": p[95], "min": float(v.min()), "max": float(v.max())},
            "hist": {"edges": edges, "counts": [int(c) for c in counts]},
        })  # fmt: skip
    return sorted(out, key=lambda m: m["model"])


async def timeseries(session: AsyncSession, f: ReportFilters,
                     bucket: Literal["minute", "hour", "day"] = "hour") -> dict[str, Any]:  # fmt: skip
    """Counts per decision and the median (nearest-rank p50) cycle time per time bucket (UTC
    bucket starts).

    Buckets run from the first to the last one holding an inspection, empty ones included
    with zero counts; more than :data:`MAX_BUCKETS` is refused (narrow ``from``/``to``).
    """
    if bucket not in BUCKETS:
        raise InvalidInput(f"bucket must be one of {', '.join(BUCKETS)}, got {bucket!r}")
    if f.start is not None and f.end is not None:
        _check_buckets(f.start, f.end, bucket)
    r = (await load(session, f)).rec
    if len(r) and (f.start is None or f.end is None):
        _check_buckets(f.start or datetime_of(int(r["t_us"].min())),
                       f.end or datetime_of(int(r["t_us"].max())), bucket)  # fmt: skip
    step_us = BUCKETS[bucket] // timedelta(microseconds=1)
    b = r["t_us"] // step_us
    data: list[dict[str, Any]] = []
    if len(r):
        b0 = int(b.min())
        idx = (b - b0).astype(np.intp)
        nb = int(idx.max()) + 1
        n = np.bincount(idx, minlength=nb)
        nd = len(DECISIONS)
        per = np.bincount(idx * nd + r["decision"], minlength=nb * nd).reshape(nb, nd).T
        med = _bucket_medians(idx, np.ascontiguousarray(r["cycle"]), nb)
        counts, per_d = n.tolist(), per.tolist()
        t0 = datetime_of(b0 * step_us)
        for k in range(nb):
            data.append({
                "t": (t0 + k * BUCKETS[bucket]).isoformat(),
                "count": counts[k],
                **{d: per_d[i][k] for i, d in enumerate(DECISIONS)},
                "cycle_p50": med[k],
            })  # fmt: skip
    return {"bucket": bucket, "data": data, "filters": f.echo()}


def _check_buckets(t0: datetime, t1: datetime, bucket: str) -> None:
    n = (_floor(t1, bucket) - _floor(t0, bucket)) // BUCKETS[bucket] + 1
    if n > MAX_BUCKETS:
        raise InvalidInput(
            f"{n} {bucket} buckets from {t0.isoformat()} to {t1.isoformat()} are more "
            f"than {MAX_BUCKETS}: narrow from/to or use a longer bucket"
        )


def _bucket_medians(idx: NDArray[np.intp], v: NDArray[np.float64], nb: int) -> list[float | None]:
    """Nearest-rank median of ``v`` (NaN = no value) within each bucket ``idx`` (0..nb-1)."""
    ok = ~np.isnan(v)
    i, x = idx[ok], v[ok]
    # By value, then stably by bucket (a radix sort on the small bucket numbers), so that
    # each bucket's values are contiguous and ascending.
    o = np.argsort(x)
    o = o[np.argsort(i[o].astype(np.uint16 if nb <= 65535 else np.int64), kind="stable")]
    xs = x[o]
    n = np.bincount(i, minlength=nb)
    first = np.concatenate(([0], np.cumsum(n)[:-1]))
    has = n > 0
    # Rank ceil(50 n / 100) within the bucket (backend.reports.stats.nearest_rank).
    at = first[has] + (50 * n[has] + 99) // 100 - 1
    out: list[float | None] = [None] * nb
    for k, val in zip(np.flatnonzero(has).tolist(), xs[at].tolist(), strict=True):
        out[k] = val
    return out


async def confusion(session: AsyncSession, f: ReportFilters) -> dict[str, Any]:
    """Confusion against the simulator's truth (rows with a truth only): rows are the true
    catalogue names, columns the decided label (the model, or ``unknown``/``failed``)."""
    rs = await load(session, f)
    r = rs.rec[rs.rec["truth"] >= 0]
    names = rs.names
    # One integer per (truth, model, decision): a 1-D unique, several times faster than rows.
    nd, nm = len(DECISIONS), max(names, default=0) + 2
    key = (r["truth"].astype(np.int64) * nm + r["model"] + 1) * nd + r["decision"]
    keys, counts = np.unique(key, return_counts=True)
    cells: dict[tuple[str, str], int] = {}
    for k, n in zip(keys.tolist(), counts.tolist(), strict=True):
        tr, rest = divmod(k, nm * nd)
        mo, de = divmod(rest, nd)
        mo -= 1
        label = (names[mo] if mo >= 0 else "unknown") if de == _REC else DECISIONS[de]
        cells[(names[tr], label)] = cells.get((names[tr], label), 0) + int(n)
    truths = sorted({t for t, _ in cells})
    models = sorted({lb for _, lb in cells} - {"unknown", "failed"})
    labels = [*models, "unknown", "failed"]
    matrix = [[0] * len(labels) for _ in truths]
    ti = {t: i for i, t in enumerate(truths)}
    li = {lb: i for i, lb in enumerate(labels)}
    for (t, lb), n in cells.items():
        matrix[ti[t]][li[lb]] += n
    return {
        "labels": labels,
        "truth": truths,
        "matrix": matrix,
        "count": int(sum(cells.values())),
        "filters": f.echo(),
    }
