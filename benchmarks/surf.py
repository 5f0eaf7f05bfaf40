"""Our SURF against OpenCV's SIFT (the baseline, measured in the same run).

- Extraction time on a 640x480 image (Oxford graf img1 resized), best of ``--repeat`` runs.
- A matching proxy on Oxford graf 1->3 (viewpoint, about 30 degrees) and boat 1->3 (zoom and
  rotation): nearest-neighbour matches with Lowe's ratio test (0.8); a match is correct when
  ``H1to3p`` maps the point of image 1 to within 3 px of its match in image 3. Printed: matches,
  correct matches, precision (correct / matches) and recall = correct / correspondences, where
  a correspondence is a keypoint of image 1 whose projection has a keypoint of image 3 within
  3 px (positions only; the full Mikolajczyk-Schmid protocol with region overlap is
  ``benchmarks.registration``). A plot of recall against 1 - precision as the ratio threshold
  sweeps 0.5..0.95 goes to ``benchmarks/out/surf-matching.png``.

Run ``python -m benchmarks.surf [--json] [--data-dir DIR] [--repeat N]``.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from rich.console import Console
from rich.table import Table

from vision.features import Features, extract
from vision.features.surf import warm_up

REPO = Path(__file__).resolve().parents[1]
DATA = REPO.parent / "shared" / "data" / "registration" / "oxford"
RATIO = 0.8
TOL_PX = 3.0
METHODS = ("sift", "surf")
SWEEP = (RATIO, *np.round(np.arange(0.5, 0.951, 0.05), 2))
OUT = REPO / "benchmarks" / "out"

out = Console()
err = Console(stderr=True)


def _read_grey(path: Path) -> np.ndarray:
    img = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
    if img is None:
        raise FileNotFoundError(path)
    return img


def _project(H: np.ndarray, xy: np.ndarray) -> np.ndarray:
    p = np.c_[xy, np.ones(len(xy))] @ H.T
    return p[:, :2] / p[:, 2:]


def _ratio_matches(a: Features, b: Features) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Nearest neighbour in ``b`` of every descriptor of ``a`` and Lowe's distance ratio."""
    knn = cv2.BFMatcher(cv2.NORM_L2).knnMatch(a.descriptors, b.descriptors, k=2)
    knn = [m for m in knn if len(m) == 2]
    q = np.array([m.queryIdx for m, _ in knn], dtype=np.int64)
    t = np.array([m.trainIdx for m, _ in knn], dtype=np.int64)
    r = np.array([m.distance / max(n.distance, 1e-12) for m, n in knn])
    return q, t, r


def match_proxy(
    a: Features, b: Features, H: np.ndarray, shape_b: tuple[int, int], ratios=(RATIO,)
) -> dict:
    """Ratio-test matches of ``a`` in ``b`` scored against the homography ``H`` (a -> b); the
    figures are for ``ratios[0]``, ``curve`` holds (ratio, matches, correct) for every ratio."""
    proj = _project(H, a.keypoints.xy)
    h, w = shape_b
    inside = (proj[:, 0] >= 0) & (proj[:, 0] < w) & (proj[:, 1] >= 0) & (proj[:, 1] < h)
    d_all = np.linalg.norm(proj[:, None, :] - b.keypoints.xy[None], axis=2)
    n_corr = int(np.sum(inside & (d_all.min(axis=1) < TOL_PX)))
    q, t, r = _ratio_matches(a, b)
    ok = np.linalg.norm(proj[q] - b.keypoints.xy[t], axis=1) < TOL_PX
    curve = [(float(x), int(np.sum(r < x)), int(np.sum(ok & (r < x)))) for x in ratios]
    _, n_match, n_ok = curve[0]
    return {
        "keypoints": [len(a), len(b)],
        "correspondences": n_corr,
        "matches": n_match,
        "correct": n_ok,
        "precision": n_ok / max(n_match, 1),
        "recall": n_ok / max(n_corr, 1),
        "curve": curve,
    }


def plot_curves(rows: list[dict], path: Path) -> None:
    """Recall (correct / correspondences) against 1 - precision as the ratio threshold sweeps."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    seqs = sorted({r["sequence"] for r in rows})
    fig, axes = plt.subplots(1, len(seqs), figsize=(4.2 * len(seqs), 3.4), squeeze=False)
    for ax, seq in zip(axes[0], seqs, strict=True):
        for r in rows:
            if r["sequence"] != seq:
                continue
            c = np.array(r["curve"][1:], dtype=float)  # skip the headline ratio
            prec = c[:, 2] / np.maximum(c[:, 1], 1)
            ax.plot(1 - prec, c[:, 2] / max(r["correspondences"], 1), "o-", ms=3, label=r["method"])
        ax.set_title(f"{seq} (ratio 0.5..0.95)")
        ax.set_xlabel("1 - precision")
        ax.set_ylabel("recall")
        ax.grid(alpha=0.3)
        ax.legend()
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=80)
    plt.close(fig)


def bench_time(img: np.ndarray, method: str, repeat: int) -> dict[str, Any]:
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        f = extract(img, method)
        times.append(time.perf_counter() - t0)
    return {"method": method, "time_ms": 1e3 * min(times), "keypoints": len(f)}


def run(data_dir: Path, repeat: int) -> dict[str, Any]:
    warm_up()
    img = cv2.resize(_read_grey(data_dir / "graf" / "img1.png"), (640, 480))
    err.log(f"timing extraction on 640x480, best of {repeat}")
    timing = [bench_time(img, m, repeat) for m in METHODS]
    rows = []
    for seq in ("graf", "boat"):
        a_img = _read_grey(data_dir / seq / "img1.png")
        b_img = _read_grey(data_dir / seq / "img3.png")
        H = np.loadtxt(data_dir / seq / "H1to3p")
        for m in METHODS:
            err.log(f"{seq} 1->3 {m}")
            r = match_proxy(extract(a_img, m), extract(b_img, m), H, b_img.shape, SWEEP)
            rows.append({"sequence": f"{seq} 1-3", "method": m, **r})
    return {"timing": timing, "matching": rows}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--json", action="store_true", help="print one JSON object last")
    ap.add_argument("--data-dir", type=Path, default=DATA, help="the Oxford sequences")
    ap.add_argument("--repeat", type=int, default=10, help="timing runs (best is kept)")
    args = ap.parse_args(argv)
    if not (args.data_dir / "graf" / "img1.png").exists():
        err.print(f"[red]Oxford data not found in {args.data_dir}[/red]")
        return 2
    res = run(args.data_dir, args.repeat)
    plot_curves(res["matching"], OUT / "surf-matching.png")
    err.log(f"plot: {OUT / 'surf-matching.png'}")

    t = Table(title="Extraction, 640x480 (graf img1 resized), best of runs")
    for c in ("method", "time ms", "keypoints"):
        t.add_column(c)
    for r in res["timing"]:
        t.add_row(r["method"], f"{r['time_ms']:.1f}", str(r["keypoints"]))
    out.print(t)
    t = Table(title=f"Matching proxy: NN + ratio {RATIO}, correct within {TOL_PX:g} px under H")
    for c in ("sequence", "method", "kp 1 / 3", "corresp.", "matches", "correct", "prec.", "rec."):
        t.add_column(c)
    for r in res["matching"]:
        t.add_row(
            r["sequence"],
            r["method"],
            f"{r['keypoints'][0]} / {r['keypoints'][1]}",
            str(r["correspondences"]),
            str(r["matches"]),
            str(r["correct"]),
            f"{r['precision']:.3f}",
            f"{r['recall']:.3f}",
        )
    out.print(t)
    if args.json:
        print(json.dumps(res))
    return 0


if __name__ == "__main__":
    sys.exit(main())
