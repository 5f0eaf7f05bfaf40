"""Benchmark of the PCA-reduced descriptors (issue 6, part 1): PCA-SIFT, GLOH and the
colour-invariant descriptor, reduced and full dimension, against OpenCV SIFT in the same run.

    python -m benchmarks.pca_descriptors [--json] [--repeats 3] [--f32-dir DIR]

For each method: descriptor length, extraction time per 640x480 image (median of
``--repeats``), brute-force matching time for the graf 1-2 pair, and on Oxford pairs
(graf 1-2, boat 1-2, bikes 1-3 -- the sequences excluded from PCA training) plus a colour-cast
pair (graf img1 against itself under a per-channel gain and a shading ramp, identity
geometry): correct matches and precision of nearest-neighbour matching with Lowe's ratio
test (0.8), a match being correct when the ground-truth homography maps it within 3 px.
``--f32-dir`` adds the same methods with float32 bases trained by
``visioncell train-pca --float32 --out DIR`` (to show that float16 storage costs nothing).
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from collections.abc import Callable
from pathlib import Path

import cv2
import numpy as np
from rich.console import Console
from rich.table import Table

from vision.features import Features, extract
from vision.features.pca import load_npz

DATA = Path(__file__).resolve().parents[1] / ".." / "shared" / "data"
err = Console(stderr=True)
PAIRS = (("graf", 2), ("boat", 2), ("bikes", 3))


def _load(seq: str, i: int, root: Path) -> np.ndarray:
    bgr = cv2.imread(str(root / "registration" / "oxford" / seq / f"img{i}.png"))
    if bgr is None:
        raise SystemExit(f"missing Oxford image {seq}/img{i}.png under {root}")
    return bgr[..., ::-1].copy()


def _cast(rgb: np.ndarray) -> np.ndarray:
    """Per-channel gain (1.2, 0.85, 0.6) times a horizontal shading ramp 0.7 -> 1.0."""
    w = rgb.shape[1]
    shade = np.linspace(0.7, 1.0, w)[None, :, None]
    return np.clip(rgb * np.array([1.2, 0.85, 0.6]) * shade, 0, 255).astype(np.uint8)


def _score(a: Features, b: Features, H: np.ndarray) -> tuple[int, float, float]:
    t = time.perf_counter()
    m = cv2.BFMatcher(cv2.NORM_L2).knnMatch(a.descriptors, b.descriptors, k=2)
    dt = time.perf_counter() - t
    good = [x[0] for x in m if len(x) == 2 and x[0].distance < 0.8 * x[1].distance]
    if not good:
        return 0, 0.0, dt
    p = a.keypoints.xy[[g.queryIdx for g in good]]
    q = b.keypoints.xy[[g.trainIdx for g in good]]
    pp = cv2.perspectiveTransform(p[None].astype(np.float64), H)[0]
    ok = np.linalg.norm(pp - q, axis=1) < 3.0
    return int(ok.sum()), float(ok.mean()), dt


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--json", action="store_true", help="print one JSON object on the last line")
    ap.add_argument("--repeats", type=int, default=3, help="timed extractions per method")
    ap.add_argument("--max-features", type=int, default=1500, help="keypoints per image")
    ap.add_argument("--data-dir", type=Path, default=DATA)
    ap.add_argument("--f32-dir", type=Path, default=None, help="float32 bases to compare")
    args = ap.parse_args()

    nf = args.max_features
    methods: dict[str, Callable[[np.ndarray], Features]] = {
        "sift (baseline)": lambda im: extract(im, "sift", max_features=nf),
        "pca-sift": lambda im: extract(im, "pca-sift", max_features=nf),
        "pca-sift full": lambda im: extract(im, "pca-sift", max_features=nf, reduce=False),
        "gloh": lambda im: extract(im, "gloh", max_features=nf),
        "gloh full": lambda im: extract(im, "gloh", max_features=nf, reduce=False),
        "color-sift": lambda im: extract(im, "color-sift", max_features=nf),
        "color-sift full": lambda im: extract(im, "color-sift", max_features=nf, reduce=False),
    }
    methods["surf"] = lambda im: extract(im, "surf", max_features=nf)
    methods["color-surf"] = lambda im: extract(im, "color-surf", max_features=nf)
    methods["color-surf full"] = lambda im: extract(im, "color-surf", max_features=nf, reduce=False)
    if args.f32_dir is not None:
        for kind in ("pca-sift", "gloh", "color-sift", "color-surf"):
            path = args.f32_dir / f"{kind}.npz"
            if path.is_file() and (kind != "color-surf" or "color-surf" in methods):
                b = load_npz(path)
                methods[f"{kind} f32"] = lambda im, k=kind, b=b: extract(
                    im, k, max_features=nf, basis=b
                )

    root = args.data_dir
    img = cv2.resize(_load("graf", 1, root), (640, 480), interpolation=cv2.INTER_AREA)
    pairs = [(f"{s} 1-{j}", _load(s, 1, root), _load(s, j, root)) for s, j in PAIRS]
    pairs += [("graf cast", pairs[0][1], _cast(pairs[0][1]))]
    hs = [np.loadtxt(root / "registration" / "oxford" / s / f"H1to{j}p") for s, j in PAIRS]
    hs.append(np.eye(3))

    results: dict[str, dict] = {}
    for name, fn in methods.items():
        err.print(f"[{len(results) + 1}/{len(methods)}] {name}")
        fn(img)  # warm-up (numba, basis loading)
        times = []
        for _ in range(args.repeats):
            t = time.perf_counter()
            f = fn(img)
            times.append(time.perf_counter() - t)
        row = {"dim": f.dim, "extract_ms": 1e3 * statistics.median(times)}
        for (label, a, b), H in zip(pairs, hs, strict=True):
            n, prec, dt = _score(fn(a), fn(b), H)
            row[label] = {"correct": n, "precision": round(prec, 3)}
            if label == "graf 1-2":
                row["match_ms"] = 1e3 * dt
        results[name] = row

    table = Table(title="PCA descriptors: 640x480 extraction, matches on Oxford pairs")
    for col in ("method", "dim", "extract ms", "match ms", *[p[0] for p in pairs]):
        table.add_column(col, justify="left" if col == "method" else "right")
    for name, r in results.items():
        cells = [f"{r[p[0]]['correct']} ({r[p[0]]['precision']:.2f})" for p in pairs]
        table.add_row(name, str(r["dim"]), f"{r['extract_ms']:.0f}", f"{r['match_ms']:.0f}", *cells)
    Console(width=150).print(table)
    print("cells: correct matches (precision); timings on a shared machine are noisy")
    if args.json:
        print(json.dumps(results))


if __name__ == "__main__":
    sys.exit(main())
