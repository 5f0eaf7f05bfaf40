"""How the colour weight of the joint colour descriptor was chosen: leave-one-scene-out
cross-validation on the real illumination scenes (issue 17).

    python -m benchmarks.registration_colour_cv [--json] [--base sift|surf] [--data-dir DIR]

The unreduced joint descriptor (grey block, then the noise-weighted m-image blocks; see
``vision.features.colour_joint``) is computed once per image with ``colour_weight=1``; the
m-image blocks are then scaled by each candidate weight (0 is the grey base itself, "m only"
drops the grey block). Per scene held out (23 folds: the 10 MIMO scenes in each of the two
encodings, and the 3 SFU scenes), the weight with the best mean gain in recall at
1-precision 0.1 over the grey base on the *other* scenes is picked and scored on the held-out
one; the table gives the mean per set of every weight, the picks, and the held-out gain. No
PCA here: the basis is trained on other images (``visioncell train-pca``).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

import numpy as np
from rich.console import Console
from rich.table import Table

from benchmarks import registration_data as rd
from vision.evaluation import evaluate_pair
from vision.features import Features, extract

REPO = Path(__file__).resolve().parents[1]
WEIGHTS: tuple[float, ...] = (0.0, 0.1, 0.25, 0.5, 1.0, 1.5)
out = Console()
err = Console(stderr=True)


def _scaled(f: Features, grey_dim: int, w: float | None) -> Features:
    d = f.descriptors.copy()
    if w is None:
        d = d[:, grey_dim:]
    else:
        d[:, grey_dim:] *= w
    return Features(f.keypoints, d, f.method, f.version, False, f.image_shape)


def recalls(pairs: list[rd.ImagePair], base: str) -> dict[Any, np.ndarray]:
    """Recall@0.1 per pair for each weight (and ``None`` = m-image blocks only)."""
    grey_dim = 128 if base == "sift" else 64
    cache: dict[int, Features] = {}

    def feats(img: np.ndarray) -> Features:
        if id(img) not in cache:
            kw = {"white_level": rd.MIMO_WHITE_LEVEL} if img.dtype == np.uint16 else {}
            cache[id(img)] = extract(
                img, f"color-{base}", max_features=2000, reduce=False, colour_weight=1.0, **kw
            )
        return cache[id(img)]

    res: dict[Any, list[float]] = {w: [] for w in (*WEIGHTS, None)}
    for k, p in enumerate(pairs):
        if k % 10 == 0:
            err.print(f"{base}: pair {k + 1}/{len(pairs)}")
        fa, fb = feats(p.a), feats(p.b)
        for w in res:
            ev = evaluate_pair(
                _scaled(fa, grey_dim, w), _scaled(fb, grey_dim, w), p.H, mask_a=p.mask_a
            )
            res[w].append(ev.recall_at_01)
    return {w: np.array(v) for w, v in res.items()}


def cross_validate(scene: np.ndarray, r: dict[Any, np.ndarray]) -> dict[str, Any]:
    """Leave one scene out: pick the weight (> 0) of best mean gain over the grey base on the
    other scenes, score it on the held-out scene."""
    cands = [w for w in WEIGHTS if w > 0]
    picks, gains = {}, []
    for sc in np.unique(scene):
        train = scene != sc
        best = max(cands, key=lambda w: float((r[w][train] - r[0.0][train]).mean()))
        picks[str(sc)] = best
        gains.append(r[best][~train] - r[0.0][~train])
    g = np.concatenate(gains)
    return {
        "picks": picks,
        "held_out_gain": float(g.mean()),
        "held_out_share_ge": float((g >= 0).mean()),
    }


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--json", action="store_true")
    ap.add_argument("--base", nargs="+", choices=("sift", "surf"), default=["sift", "surf"])
    ap.add_argument("--data-dir", type=Path, default=REPO.parent / "shared" / "data")
    args = ap.parse_args(argv)
    pairs, skipped = rd.real_illumination_pairs(args.data_dir)
    for s, why in skipped.items():
        err.print(f"skipping {s}: {why}")
    if not pairs:
        err.print("no real illumination data: nothing to cross-validate")
        return 1
    seqs = np.array([p.sequence for p in pairs])
    scene = np.array([f"{p.sequence}:{p.name.split('/')[0]}" for p in pairs])
    result: dict[str, Any] = {}
    for base in args.base:
        r = recalls(pairs, base)
        cv = cross_validate(scene, r)
        t = Table(title=f"color-{base} joint layout, recall@0.1 by colour weight (no PCA)")
        t.add_column("weight")
        for s in rd.REAL_ILLUMINATION_SETS:
            t.add_column(s, justify="right")
        t.add_column("all", justify="right")
        t.add_column(">= grey base", justify="right")
        for w, v in r.items():
            name = "m-images only" if w is None else ("0 (grey base)" if w == 0 else f"{w:g}")
            cells = [f"{v[seqs == s].mean():.3f}" for s in rd.REAL_ILLUMINATION_SETS]
            t.add_row(name, *cells, f"{v.mean():.3f}", f"{100 * (v >= r[0.0]).mean():.0f} %")
        out.print(t)
        picked = sorted(set(cv["picks"].values()))
        out.print(
            f"leave-one-scene-out: picked {picked} ({len(cv['picks'])} folds), held-out gain "
            f"over the grey base {cv['held_out_gain']:+.4f}, >= grey base on "
            f"{100 * cv['held_out_share_ge']:.0f} % of the pairs"
        )
        result[base] = {
            "by_weight": {
                ("m_only" if w is None else f"{w:g}"): {
                    **{s: float(v[seqs == s].mean()) for s in rd.REAL_ILLUMINATION_SETS},
                    "all": float(v.mean()),
                }
                for w, v in r.items()
            },
            **cv,
        }
    if args.json:
        print(json.dumps(result))
    return 0


if __name__ == "__main__":
    sys.exit(main())
