"""How much the joint colour descriptor's colour blocks weigh on the real illumination images
(issue 17): the mean noise weight per image against its brightness.

    python -m benchmarks.registration_colour_weights [--json] [--base sift|surf] [--docs]
                                                     [--data-dir DIR]

For every image of the real illumination pairs (``registration_data.real_illumination_pairs``)
the keypoints and the noise weights of the two colour blocks (``vision.features.colour_joint.
block_snr_weight``: the Wiener gain of the m-image gradient energy over what the sensor noise
measured in that image would give) are computed as ``extract(..., "color-<base>")`` does; the
table gives, per set, the mean weight, the share of blocks of weight exactly 0 (there the
descriptor is exactly the grey one) and the mean image brightness; the plot shows one point
per image. The grey base's weight is 0 by definition, so this is the measurement of how much
the colour can add at all. Plot to ``benchmarks/out/`` (``--docs``: ``docs/img/``).
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
from vision.features.colour import detection_grey
from vision.features.colour_joint import NOISE_FLOOR, SATURATION, joint_parts

REPO = Path(__file__).resolve().parents[1]
out = Console()
err = Console(stderr=True)


def image_weights(img: np.ndarray, base: str) -> tuple[float, float, float, int]:
    """(mean weight, share of weight-0 blocks, mean relative brightness, keypoints)."""
    wl = rd.MIMO_WHITE_LEVEL if img.dtype == np.uint16 else 255.0
    grey = detection_grey(img, white_level=wl)
    colour = {"transfer": "linear", "white_level": wl, "noise_floor": NOISE_FLOOR}
    colour["saturation"] = SATURATION
    detect = {"max_features": 2000, "threshold": None, "mask": None}
    kp, _, _, c = joint_parts(img, grey, base, detect, {}, colour)
    bright = float(img.astype(np.float64).mean() / wl)
    if len(kp) == 0:
        return 0.0, 1.0, bright, 0
    return float(c.mean()), float((c == 0).mean()), bright, len(kp)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--json", action="store_true")
    ap.add_argument("--base", choices=("sift", "surf"), default="sift")
    ap.add_argument("--data-dir", type=Path, default=REPO.parent / "shared" / "data")
    ap.add_argument("--docs", action="store_true", help="write the plot to docs/img")
    args = ap.parse_args(argv)
    pairs, skipped = rd.real_illumination_pairs(args.data_dir)
    for s, why in skipped.items():
        err.print(f"skipping {s}: {why}")
    if not pairs:
        err.print("no real illumination data")
        return 1
    seen: dict[int, tuple[str, np.ndarray]] = {}
    for p in pairs:
        for img in (p.a, p.b):
            seen.setdefault(id(img), (p.sequence, img))
    rows: list[dict[str, Any]] = []
    for k, (seq, img) in enumerate(seen.values()):
        if k % 10 == 0:
            err.print(f"image {k + 1}/{len(seen)}")
        w, zero, bright, n = image_weights(img, args.base)
        rows.append({"set": seq, "weight": w, "zero": zero, "brightness": bright, "n": n})
    t = Table(title=f"color-{args.base}: noise weights of the colour blocks per image")
    for col in ("set", "images", "mean weight", "weight 0", "mean brightness"):
        t.add_column(col, justify="right")
    result: dict[str, Any] = {"base": args.base, "sets": {}}
    for s in rd.REAL_ILLUMINATION_SETS:
        rs = [r for r in rows if r["set"] == s]
        if not rs:
            continue
        agg = {
            "images": len(rs),
            "mean_weight": float(np.mean([r["weight"] for r in rs])),
            "share_zero": float(np.mean([r["zero"] for r in rs])),
            "mean_brightness": float(np.mean([r["brightness"] for r in rs])),
        }
        result["sets"][s] = agg
        t.add_row(
            s,
            str(agg["images"]),
            f"{agg['mean_weight']:.3f}",
            f"{100 * agg['share_zero']:.0f} %",
            f"{agg['mean_brightness']:.3f}",
        )
    out.print(t)
    import matplotlib
    import matplotlib.ticker

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(5.0, 3.4))
    for s, mk in zip(rd.REAL_ILLUMINATION_SETS, "os^", strict=False):
        rs = [r for r in rows if r["set"] == s]
        if rs:
            ax.plot([r["brightness"] for r in rs], [r["weight"] for r in rs], mk, ms=4, label=s)
    ax.set_xscale("log")
    ax.xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
    ax.set_xlabel("mean image value / white level")
    ax.set_ylabel("mean colour-block noise weight")
    ax.set_title(f"color-{args.base}: colour-block weight per image (0: exactly grey)", fontsize=9)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7)
    fig.tight_layout()
    dest = (REPO / "docs" / "img") if args.docs else (REPO / "benchmarks" / "out")
    dest.mkdir(parents=True, exist_ok=True)
    path = dest / f"registration_colour_weights_{args.base}.png"
    fig.savefig(path, dpi=110)
    plt.close(fig)
    out.print(f"plot: {path}")
    result["plot"] = str(path)
    if args.json:
        print(json.dumps(result))
    return 0


if __name__ == "__main__":
    sys.exit(main())
