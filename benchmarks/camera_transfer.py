"""Which transfer curve to read a camera's 8-bit images with, for the colour tie-break.

The tie-break's colour signature (:func:`vision.recognition.colour.colour_signature`) is
meant to be unchanged by the light (equation 17: ratios against the region's median) and
to tell objects of different colours apart.  On the real illumination sets (fixed cameras,
each scene under several lamps: MIMO as 8-bit sRGB and as 16-bit linear RGB, SFU as 8-bit
linear RGB) every image's signature over its usable pixels is computed with
``transfer="linear"`` and ``transfer="srgb"``, and compared:

* ``within``: mean distance between two images of one scene under different lamps (the
  light's change: lower is better);
* ``between``: mean distance between two scenes under the same lamps;
* ``separation``: between / within (higher is better);
* ``nn``: share of images whose nearest other image (by signature) is of the same scene.

The 16-bit linear set is reduced to 8-bit linear values (a white level common to the whole
set, its 99.9th percentile, at 250), as a linear camera delivering 8 bits would.
``python -m benchmarks.camera_transfer [--json]``; both curves run in the same process (each
is the other's baseline).
"""

from __future__ import annotations

import argparse
import itertools
import json
import sys
from collections import defaultdict
from pathlib import Path

import cv2
import numpy as np

from vision.recognition.colour import colour_distance, colour_signature

REPO = Path(__file__).resolve().parents[1]
TRANSFERS = ("linear", "srgb")


def _mimo(root: Path, kind: str) -> list[tuple[str, str, np.ndarray, np.ndarray]]:
    """(scene, light, RGB uint8, usable-pixel mask) of the MIMO ``kind`` set."""
    out = []
    raw = []
    for p in sorted((root / kind).glob("*.png")):
        scene, light = p.stem.split("_", 1)
        img = cv2.imread(str(p), cv2.IMREAD_UNCHANGED)
        mask = cv2.imread(str(root / "masks" / p.name), cv2.IMREAD_GRAYSCALE) > 0
        raw.append((scene, light, cv2.cvtColor(img, cv2.COLOR_BGR2RGB), mask))
    if kind == "linear16":
        white = float(np.percentile(np.concatenate([r[2].ravel() for r in raw]), 99.9))
        for scene, light, img, mask in raw:
            rgb = np.clip(img.astype(np.float64) * (250.0 / white), 0, 255).astype(np.uint8)
            out.append((scene, light, rgb, mask))
        return out
    return raw


def _sfu(root: Path) -> list[tuple[str, str, np.ndarray, np.ndarray]]:
    out = []
    for p in sorted(root.glob("*.tif")):
        scene, light = p.stem.split("_", 1)
        rgb = cv2.cvtColor(cv2.imread(str(p), cv2.IMREAD_COLOR), cv2.COLOR_BGR2RGB)
        out.append((scene, light, rgb, np.ones(rgb.shape[:2], bool)))
    return out


def measure(images: list[tuple[str, str, np.ndarray, np.ndarray]], transfer: str) -> dict:
    """The figures of the module docstring for one set and one curve."""
    sigs = []
    for scene, light, rgb, mask in images:
        s = colour_signature(rgb, mask, transfer=transfer)
        if s is not None:
            sigs.append((scene, light, s))
    within, between = [], []
    by_light: dict[str, list] = defaultdict(list)
    for scene, light, s in sigs:
        by_light[light].append((scene, s))
    for a, b in itertools.combinations(sigs, 2):
        if a[0] == b[0]:
            within.append(colour_distance(a[2], b[2]))
    for group in by_light.values():
        for a, b in itertools.combinations(group, 2):
            between.append(colour_distance(a[1], b[1]))
    hits = 0
    for i, (scene, _l, s) in enumerate(sigs):
        d = [(colour_distance(s, t), sc) for j, (sc, _m, t) in enumerate(sigs) if j != i]
        hits += min(d)[1] == scene
    w, b = float(np.mean(within)), float(np.mean(between)) if between else float("nan")
    return {"images": len(sigs), "within": round(w, 3), "between": round(b, 3),
            "separation": round(b / w, 3) if w > 0 else None,
            "nn": round(hits / len(sigs), 3)}  # fmt: skip


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--json", action="store_true", help="print one JSON object on the last line")
    ap.add_argument("--data-dir", type=Path, default=REPO.parent / "shared" / "data")
    args = ap.parse_args(argv)
    root = args.data_dir / "illumination"
    if not (root / "mimo" / "srgb8").is_dir():
        print(f"the illumination sets are absent from {root} (see the data README)")
        return 2
    sets = {
        "mimo-srgb8": _mimo(root / "mimo", "srgb8"),
        "mimo-linear16": _mimo(root / "mimo", "linear16"),
        "sfu-linear8": _sfu(root / "sfu"),
    }
    rows = {name: {t: measure(imgs, t) for t in TRANSFERS} for name, imgs in sets.items()}
    print(f"{'set':<15} {'transfer':<8} {'images':>6} {'within':>7} {'between':>8} "
          f"{'separation':>10} {'nn':>6}")  # fmt: skip
    for name, by_t in rows.items():
        for t, r in by_t.items():
            print(f"{name:<15} {t:<8} {r['images']:>6} {r['within']:>7.3f} {r['between']:>8.3f} "
                  f"{r['separation']:>10.3f} {r['nn']:>6.3f}")  # fmt: skip
    if args.json:
        print(json.dumps({"benchmark": "camera_transfer", "sets": rows}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
