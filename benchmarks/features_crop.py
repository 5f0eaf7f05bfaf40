"""Features inside a mask: from a crop round the mask (what ``ViewIndex.features`` does)
against the whole image (the baseline), on the taught views of a database.

For every sampled trained view with a mask: CPU time of each extraction (thread time, so
a shared machine's load matters less), the share of the whole image's keypoints found at the
same place in the crop's, and the share of those with the same descriptor.  The database
is one ``benchmarks.inspection --taught-db FILE`` wrote (the twelve parts, four yaws)::

    .venv/bin/python -m benchmarks.features_crop [--db FILE] [--views 40] [--json]

(without ``--db``, ``benchmarks/out/taught4.db``, taught first when it is missing).
"""

from __future__ import annotations

import argparse
import json
import sqlite3
import sys
import time
from pathlib import Path

import cv2
import numpy as np


def _decode(blob: bytes, flag: int) -> np.ndarray:
    return cv2.imdecode(np.frombuffer(blob, np.uint8), flag)


def measure(db: Path, views: int) -> dict:
    import vision.recognition.index as vi
    from backend.recognition.index import LiveIndex

    con = sqlite3.connect(f"file:{db}?mode=ro", uri=True)
    try:
        rows = con.execute(
            "select id, image_png, mask_png from trained_views where mask_png is not null "
            "order by id"
        ).fetchall()
    finally:
        con.close()
    if not rows:
        raise SystemExit(f"{db}: no trained views with a mask")
    step = max(1, len(rows) // views)
    rows = rows[::step][:views]
    live = LiveIndex()
    t_crop, t_whole, same, same_desc = [], [], [], []
    for k, (_vid, ip, mp) in enumerate(rows):
        img = cv2.cvtColor(_decode(ip, cv2.IMREAD_COLOR), cv2.COLOR_BGR2RGB)
        mask = _decode(mp, cv2.IMREAD_GRAYSCALE) > 0
        with live.reading() as ix:
            t = time.thread_time()
            c = ix.features(img, mask=mask)
            t_crop.append(time.thread_time() - t)
            saved, vi.CROP_METHODS = vi.CROP_METHODS, frozenset()
            try:
                t = time.thread_time()
                w = ix.features(img, mask=mask)
                t_whole.append(time.thread_time() - t)
            finally:
                vi.CROP_METHODS = saved
        if len(w) and len(c):
            kw, kc = w.keypoints, c.keypoints  # same place, size and orientation (SIFT
            d = (  # gives a place one keypoint per dominant orientation)
                np.linalg.norm(kw.xy[:, None] - kc.xy[None], axis=2)
                + np.abs(kw.size_px[:, None] - kc.size_px[None])
                + np.abs(np.angle(np.exp(1j * (kw.angle_rad[:, None] - kc.angle_rad[None]))))
            )
            near = d.argmin(axis=1)
            hit = d[np.arange(len(w)), near] < 0.05
            same.append(float(hit.mean()))
            dd = np.abs(w.descriptors[hit].astype(float) - c.descriptors[near[hit]].astype(float))
            same_desc.append(float((dd.max(axis=1) < 1e-3).mean()) if hit.any() else 0.0)
        print(f"[{k + 1}/{len(rows)}] views", file=sys.stderr, flush=True)
    ms = lambda v, q: float(np.percentile(v, q) * 1e3)  # noqa: E731
    return {
        "views": len(rows),
        "whole_ms_p50": ms(t_whole, 50), "whole_ms_p95": ms(t_whole, 95),
        "crop_ms_p50": ms(t_crop, 50), "crop_ms_p95": ms(t_crop, 95),
        "ratio_p50": float(np.median(np.array(t_crop) / np.array(t_whole))),
        "same_keypoints_p50": float(np.median(same)), "same_keypoints_min": float(min(same)),
        "same_descriptors_p50": float(np.median(same_desc)),
    }  # fmt: skip


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument(
        "--db", type=Path, default=Path("benchmarks/out/taught4.db"),
        help="a taught SQLite database (taught first with benchmarks.inspection if missing)",
    )  # fmt: skip
    ap.add_argument("--views", type=int, default=40, help="views sampled (1..2000)")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args(argv)
    if not 1 <= args.views <= 2000:
        ap.error(f"--views must be in 1..2000, got {args.views}")
    if not args.db.is_file():
        from benchmarks import inspection

        print(
            f"{args.db}: teaching the twelve models first (benchmarks.inspection)", file=sys.stderr
        )
        inspection.main(["--objects", "0", "--objects-constant", "0", "--objects-light", "0",
                         "--objects-sort", "0", "--taught-db", str(args.db)])  # fmt: skip
    r = measure(args.db, args.views)
    print(f"features inside a mask, {r['views']} taught views (CPU ms per view)")
    print("| extraction | p50 ms | p95 ms |")
    print("|---|---|---|")
    print(f"| whole image (baseline) | {r['whole_ms_p50']:.1f} | {r['whole_ms_p95']:.1f} |")
    print(f"| crop round the mask | {r['crop_ms_p50']:.1f} | {r['crop_ms_p95']:.1f} |")
    print(f"crop / whole, median per view: {r['ratio_p50']:.2f}")
    print(f"whole image's keypoints found in the crop: median {r['same_keypoints_p50']:.0%}, "
          f"least {r['same_keypoints_min']:.0%}; of those with the same descriptor: "
          f"median {r['same_descriptors_p50']:.0%}")  # fmt: skip
    if args.json:
        print(json.dumps(r))


if __name__ == "__main__":
    main()
