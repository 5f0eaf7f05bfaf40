"""Segmentation benchmark: our snake and level set against scikit-image, same images, same starts.

Run ``python -m benchmarks.segmentation [--json] [--repeats N] [--grid] [--providers skimage,sim]``.

For every case of :mod:`benchmarks.segmentation_cases` (image, object, reference mask, initial
ellipse) of the providers asked for (default both: ``skimage``, four photographs, and ``sim``,
five wheels rendered by the simulated cell; a provider that cannot run here, e.g. ``sim``
without MuJoCo rendering, is skipped with its reason printed) it runs, in one process:

- snakes: :func:`vision.segmentation.active_contour` against
  ``skimage.segmentation.active_contour``, both from the same initial contour on the whole
  image;
- level sets: :func:`vision.segmentation.chan_vese` (colour) against
  ``skimage.segmentation.morphological_chan_vese`` (grey: it has no colour mode; our level set
  on the same grey image is reported too), both on the same crop (the initial contour's
  bounding box grown by 16 px: region-based models compare the object with what surrounds
  it) and from the same initial region (the filled initial contour); and our localised level
  set (``local_radius_px``, Lankton and Tannenbaum 2008, colour) on the same crop and start,
  its window ``LEVELSET_LOCAL["local_radius_frac"]`` times the initial ellipse's minor
  semi-axis.

It reports IoU against the reference mask and the wall time per image (median of
``--repeats`` runs, after one warm-up call per method so that one-off costs such as loading
Numba's compiled code are not counted, for either side), with ratios, checks the targets,
prints a table (and with ``--json`` one JSON object on the last line), and writes the figures
``benchmarks/out/segmentation.png`` (photographs), ``benchmarks/out/segmentation_wheels.png``
(rendered wheels) and ``benchmarks/out/levelset_evolution.png`` (git-ignored); with
``--docs`` it also refreshes the small copies in ``docs/img/`` that the README shows.

Parameters are fixed below for both sides.  They are the best mean IoU over the four
photographs of the small grids in :data:`GRIDS` (one setting per method, for all images);
``--grid`` reruns those grids on the photographs and prints every row, so the choice can be
checked.  The rendered wheels were not used to choose any parameter: they are held-out
test images.  scikit-image's
``active_contour`` keeps its own defaults otherwise (``w_line=0``, ``w_edge=1``,
``max_num_iter=2500``, ``convergence=0.1``, ``boundary_condition="periodic"``) and gets the image
pre-smoothed by ``skimage.filters.gaussian(sigma)`` as its documentation's example does; that
smoothing is timed as part of it.
"""

from __future__ import annotations

import argparse
import itertools
import json
import statistics
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray
from rich.console import Console
from rich.progress import Progress
from rich.table import Table

from benchmarks.segmentation_cases import PROVIDERS, Case, all_cases, roi_box
from vision.segmentation import (
    active_contour,
    chan_vese,
    circle_contour,
    iou,
    mask_from_contour,
)

OUT_DIR = Path(__file__).resolve().parent / "out"
DOCS_IMG = Path(__file__).resolve().parent.parent / "docs" / "img"

SNAKE_OURS: dict[str, Any] = {"balloon": -0.6, "alpha": 0.3, "beta": 5.0, "sigma_px": 1.5}
SNAKE_SKIMAGE: dict[str, Any] = {"sigma": 3.0, "alpha": 0.1, "beta": 1.0, "gamma": 0.01}
LEVELSET_OURS: dict[str, Any] = {"mu": 0.8, "sigma_px": 2.5, "band_px": 1}
LEVELSET_MCV: dict[str, Any] = {"smoothing": 3, "num_iter": 50}
#: Localised Chan-Vese (Lankton and Tannenbaum 2008): ``local_radius_frac`` is the window's
#: standard deviation over the initial ellipse's minor semi-axis (a rule fixed before the run:
#: the window scales with the object's expected size); chosen by the grid on the photographs.
LEVELSET_LOCAL: dict[str, Any] = {
    "mu": 0.8,
    "sigma_px": 2.5,
    "band_px": 1,
    "local_radius_frac": 0.1,
}

GRIDS: dict[str, dict[str, list[Any]]] = {
    "snake_ours": {
        "balloon": [-0.6, -1.0],
        "alpha": [0.1, 0.3],
        "beta": [5.0],
        "sigma_px": [1.5, 2.0],
    },
    "snake_skimage": {
        "sigma": [1.0, 2.0, 3.0],
        "alpha": [0.015, 0.1],
        "beta": [1.0, 10.0],
        "gamma": [0.001, 0.01],
    },
    "levelset_ours": {"mu": [0.4, 0.6, 0.8], "sigma_px": [2.5, 3.0], "band_px": [1]},
    "levelset_mcv": {"smoothing": [1, 2, 3], "num_iter": [25, 50, 100, 200]},
    "levelset_local": {
        "mu": [0.4, 0.8],
        "sigma_px": [2.5],
        "band_px": [1],
        "local_radius_frac": [0.05, 0.1, 0.2, 0.3, 0.5],
    },
}

TARGETS = {"snake_speedup": 10.0, "levelset_speedup": 3.0}


# ---------------------------------------------------------------------------------------
# The four methods
# ---------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Outcome:
    """One method on one case: full-image mask, its IoU, time, and what to draw."""

    mask: NDArray[np.bool_]
    iou: float
    seconds: float
    contour: NDArray[np.float64] | None = None
    extra: dict[str, Any] = field(default_factory=dict)


def _timed(fn: Callable[[], Any], repeats: int) -> tuple[Any, float]:
    times, out = [], None
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t0)
    return out, statistics.median(times)


def snake_ours(case: Case, params: dict[str, Any], repeats: int = 1) -> Outcome:
    res, dt = _timed(lambda: active_contour(case.image, case.init, **params), repeats)
    return Outcome(
        res.mask,
        iou(res.mask, case.reference),
        dt,
        res.contour,
        {"iterations": res.iterations, "converged": res.converged},
    )


def snake_skimage(case: Case, params: dict[str, Any], repeats: int = 1) -> Outcome:
    from skimage.filters import gaussian
    from skimage.segmentation import active_contour as sk_active_contour

    p = dict(params)
    sigma = p.pop("sigma")
    channel_axis = -1 if case.image.ndim == 3 else None

    def run() -> NDArray[np.float64]:
        smooth = gaussian(case.image, sigma=sigma, channel_axis=channel_axis, preserve_range=False)
        return sk_active_contour(smooth, case.init[:, ::-1], **p)[:, ::-1]  # (row, col) <-> (x, y)

    contour, dt = _timed(run, repeats)
    mask = mask_from_contour(contour, case.image.shape)
    return Outcome(mask, iou(mask, case.reference), dt, contour)


def _crop(case: Case) -> tuple[NDArray[np.uint8], NDArray[np.bool_], tuple[int, int, int, int]]:
    box = roi_box(case.init, case.image.shape)
    x0, y0, x1, y1 = box
    crop = np.ascontiguousarray(case.image[y0:y1, x0:x1])
    return crop, mask_from_contour(case.init - [x0, y0], crop.shape), box


def _paste(
    mask: NDArray[np.bool_], box: tuple[int, int, int, int], shape: tuple[int, ...]
) -> NDArray[np.bool_]:
    full = np.zeros(shape[:2], dtype=bool)
    x0, y0, x1, y1 = box
    full[y0:y1, x0:x1] = mask
    return full


def _grey(img: NDArray[np.uint8]) -> NDArray[np.float64]:
    from skimage.color import rgb2gray
    from skimage.util import img_as_float

    return rgb2gray(img) if img.ndim == 3 else img_as_float(img)


def minor_semi_axis(init: NDArray[np.float64]) -> float:
    """Half the smaller side of the initial contour's bounding box (an ellipse's minor
    semi-axis for the benchmark's axis-aligned ellipses), pixels."""
    return 0.5 * float(np.min(init.max(axis=0) - init.min(axis=0)))


def levelset_ours(
    case: Case, params: dict[str, Any], repeats: int = 1, *, grey: bool = False
) -> Outcome:
    crop, init, box = _crop(case)
    image = _grey(crop) if grey else crop
    params = dict(params)
    frac = params.pop("local_radius_frac", None)
    if frac is not None:
        params["local_radius_px"] = frac * minor_semi_axis(case.init)
    res, dt = _timed(lambda: chan_vese(image, init, **params), repeats)
    mask = _paste(res.mask, box, case.image.shape)
    return Outcome(mask, iou(mask, case.reference), dt, None, {"iterations": res.iterations})


def levelset_mcv(case: Case, params: dict[str, Any], repeats: int = 1) -> Outcome:
    from skimage.segmentation import morphological_chan_vese

    crop, init, box = _crop(case)
    grey = _grey(crop)
    res, dt = _timed(
        lambda: morphological_chan_vese(grey, init_level_set=init.astype(np.int8), **params),
        repeats,
    )
    mask = _paste(res.astype(bool), box, case.image.shape)
    return Outcome(mask, iou(mask, case.reference), dt)


METHODS: dict[str, Callable[..., Outcome]] = {
    "snake_ours": snake_ours,
    "snake_skimage": snake_skimage,
    "levelset_ours": levelset_ours,
    "levelset_mcv": levelset_mcv,
    "levelset_local": levelset_ours,
}


def _warm_up() -> None:
    """One call per method on a tiny synthetic image (loads compiled code and imports)."""
    yy, xx = np.mgrid[:64, :64]
    img = (((xx - 32) ** 2 + (yy - 32) ** 2 < 15**2) * 200 + 20).astype(np.uint8)
    case = Case("warm", "synthetic", "", img, img > 100, circle_contour((32, 32), 24.0, 60))
    for name, fn in METHODS.items():
        params = {
            "snake_ours": SNAKE_OURS,
            "snake_skimage": SNAKE_SKIMAGE,
            "levelset_ours": LEVELSET_OURS,
            "levelset_mcv": LEVELSET_MCV,
            "levelset_local": LEVELSET_LOCAL,
        }[name]
        fn(case, params)


# ---------------------------------------------------------------------------------------
# Runs
# ---------------------------------------------------------------------------------------


def run_benchmark(
    cases: list[Case], repeats: int, progress: Callable[[str], None]
) -> list[dict[str, Any]]:
    rows = []
    for case in cases:
        progress(f"{case.name}: our snake")
        so = snake_ours(case, SNAKE_OURS, repeats)
        progress(f"{case.name}: scikit-image active_contour")
        ss = snake_skimage(case, SNAKE_SKIMAGE, repeats)
        progress(f"{case.name}: our level set")
        lo = levelset_ours(case, LEVELSET_OURS, repeats)
        lg = levelset_ours(case, LEVELSET_OURS, repeats, grey=True)
        progress(f"{case.name}: our localised level set")
        ll = levelset_ours(case, LEVELSET_LOCAL, repeats)
        progress(f"{case.name}: morphological_chan_vese")
        lm = levelset_mcv(case, LEVELSET_MCV, repeats)
        rows.append(
            {
                "case": case,
                "snake_ours": so,
                "snake_skimage": ss,
                "levelset_ours": lo,
                "levelset_ours_grey": lg,
                "levelset_local": ll,
                "levelset_mcv": lm,
            }
        )
    return rows


#: The provider whose images choose the parameters (the others are held out).
TUNING_PROVIDER = "skimage"


def run_grid(cases: list[Case], progress: Callable[[str], None]) -> dict[str, list[dict[str, Any]]]:
    """Every setting of :data:`GRIDS` on the tuning cases (:data:`TUNING_PROVIDER`); rows
    sorted best first (mean IoU)."""
    cases = [c for c in cases if c.provider == TUNING_PROVIDER]
    if not cases:
        raise ValueError(f"--grid needs the {TUNING_PROVIDER!r} provider's images")
    out: dict[str, list[dict[str, Any]]] = {}
    for method, grid in GRIDS.items():
        rows = []
        for values in itertools.product(*grid.values()):
            params = dict(zip(grid, values, strict=True))
            progress(f"grid {method} {params}")
            res = [METHODS[method](case, params) for case in cases]
            rows.append(
                {
                    "params": params,
                    "iou": [r.iou for r in res],
                    "mean_iou": float(np.mean([r.iou for r in res])),
                    "seconds": [r.seconds for r in res],
                }
            )
        rows.sort(key=lambda r: (-round(r["mean_iou"], 4), sum(r["seconds"])))
        out[method] = rows
    return out


def _targets(cases: list[dict[str, Any]]) -> dict[str, Any]:
    snake_speed = min(c["snake"]["speedup"] for c in cases)
    ls_speed = min(c["levelset"]["speedup"] for c in cases)
    loc_speed = min(c["levelset"]["speedup_local"] for c in cases)
    return {
        "snake_iou_ge_skimage_every_image": all(
            c["snake"]["iou_ours"] >= c["snake"]["iou_skimage"] for c in cases
        ),
        "snake_min_speedup": snake_speed,
        "snake_speedup_met": snake_speed >= TARGETS["snake_speedup"],
        "levelset_iou_ge_mcv_every_image": all(
            c["levelset"]["iou_ours"] >= c["levelset"]["iou_mcv"] for c in cases
        ),
        "levelset_min_speedup": ls_speed,
        "levelset_speedup_met": ls_speed >= TARGETS["levelset_speedup"],
        "levelset_local_iou_ge_mcv_every_image": all(
            c["levelset"]["iou_local"] >= c["levelset"]["iou_mcv"] for c in cases
        ),
        "levelset_local_min_speedup": loc_speed,
        "levelset_local_speedup_met": loc_speed >= TARGETS["levelset_speedup"],
    }


def summarise(rows: list[dict[str, Any]], skipped: dict[str, str] | None = None) -> dict[str, Any]:
    """Per-case figures, ratios and the targets (over all images and per provider), as plain
    data (the JSON)."""
    cases = []
    for r in rows:
        so, ss, lo, lg, ll, lm = (
            r[k]
            for k in (
                "snake_ours",
                "snake_skimage",
                "levelset_ours",
                "levelset_ours_grey",
                "levelset_local",
                "levelset_mcv",
            )
        )
        cases.append(
            {
                "case": r["case"].name,
                "provider": r["case"].provider,
                "object": r["case"].description,
                "size": list(r["case"].image.shape[:2]),
                "snake": {
                    "iou_ours": so.iou,
                    "iou_skimage": ss.iou,
                    "s_ours": so.seconds,
                    "s_skimage": ss.seconds,
                    "speedup": ss.seconds / so.seconds,
                    "iterations_ours": so.extra["iterations"],
                },
                "levelset": {
                    "iou_ours": lo.iou,
                    "iou_ours_grey": lg.iou,
                    "iou_local": ll.iou,
                    "iou_mcv": lm.iou,
                    "s_ours": lo.seconds,
                    "s_ours_grey": lg.seconds,
                    "s_local": ll.seconds,
                    "s_mcv": lm.seconds,
                    "speedup": lm.seconds / lo.seconds,
                    "speedup_local": lm.seconds / ll.seconds,
                    "local_radius_px": LEVELSET_LOCAL["local_radius_frac"]
                    * minor_semi_axis(r["case"].init),
                },
            }
        )
    providers = list(dict.fromkeys(c["provider"] for c in cases))
    return {
        "benchmark": "segmentation",
        "cases": cases,
        "settings": {
            "snake_ours": SNAKE_OURS,
            "snake_skimage": SNAKE_SKIMAGE,
            "levelset_ours": LEVELSET_OURS,
            "levelset_mcv": LEVELSET_MCV,
            "levelset_local": LEVELSET_LOCAL,
        },
        "targets": _targets(cases),
        "targets_by_provider": {
            p: _targets([c for c in cases if c["provider"] == p]) for p in providers
        },
        "skipped_providers": dict(skipped or {}),
    }


def print_table(summary: dict[str, Any], console: Console) -> None:
    t = Table(
        title="Snakes: ours vs skimage.segmentation.active_contour (IoU vs reference, wall time)"
    )
    for col in (
        "image",
        "source",
        "object",
        "IoU ours",
        "IoU skimage",
        "ms ours",
        "ms skimage",
        "speed-up",
    ):
        t.add_column(col, justify="right" if col not in ("image", "source", "object") else "left")
    for c in summary["cases"]:
        s = c["snake"]
        t.add_row(
            c["case"],
            c["provider"],
            c["object"],
            f"{s['iou_ours']:.3f}",
            f"{s['iou_skimage']:.3f}",
            f"{1e3 * s['s_ours']:.1f}",
            f"{1e3 * s['s_skimage']:.0f}",
            f"{s['speedup']:.0f}x",
        )
    console.print(t)
    t = Table(
        title="Level sets: ours global (colour; grey), ours localised (colour) vs skimage "
        "morphological_chan_vese (grey)"
    )
    for col in (
        "image",
        "IoU ours",
        "IoU ours grey",
        "IoU local",
        "IoU MCV",
        "ms ours",
        "ms ours grey",
        "ms local",
        "ms MCV",
        "speed-up",
        "speed-up local",
    ):
        t.add_column(col, justify="right" if col != "image" else "left")
    for c in summary["cases"]:
        s = c["levelset"]
        t.add_row(
            c["case"],
            f"{s['iou_ours']:.3f}",
            f"{s['iou_ours_grey']:.3f}",
            f"{s['iou_local']:.3f}",
            f"{s['iou_mcv']:.3f}",
            f"{1e3 * s['s_ours']:.1f}",
            f"{1e3 * s['s_ours_grey']:.1f}",
            f"{1e3 * s['s_local']:.1f}",
            f"{1e3 * s['s_mcv']:.0f}",
            f"{s['speedup']:.1f}x",
            f"{s['speedup_local']:.1f}x",
        )
    console.print(t)
    for provider, reason in summary["skipped_providers"].items():
        console.print(f"provider {provider!r} skipped: {reason}")
    scopes = [("all images", summary["targets"])]
    if len(summary["targets_by_provider"]) > 1:
        scopes += [(f"{p} images", tg) for p, tg in summary["targets_by_provider"].items()]
    for scope, tg in scopes:
        _print_targets(scope, tg, console)


def _print_targets(scope: str, tg: dict[str, Any], console: Console) -> None:
    console.print(
        f"{scope}: snake: IoU >= skimage on every image: {'MET' if tg['snake_iou_ge_skimage_every_image'] else 'MISSED'}; "
        f"slowest speed-up {tg['snake_min_speedup']:.1f}x (target {TARGETS['snake_speedup']:.0f}x): "
        f"{'MET' if tg['snake_speedup_met'] else 'MISSED'}"
    )
    for label, key in (("global", "levelset"), ("localised", "levelset_local")):
        console.print(
            f"{scope}: level set ({label}): IoU >= MCV on every image: "
            f"{'MET' if tg[f'{key}_iou_ge_mcv_every_image'] else 'MISSED'}; "
            f"slowest speed-up {tg[f'{key}_min_speedup']:.1f}x "
            f"(target {TARGETS['levelset_speedup']:.0f}x): "
            f"{'MET' if tg[f'{key}_speedup_met'] else 'MISSED'}"
        )


def figure_paths(stem: str, *, docs: bool) -> tuple[Path, Path | None]:
    """Where figure ``stem`` goes: ``benchmarks/out/`` always, ``docs/img/`` only with ``docs``."""
    return OUT_DIR / f"{stem}.png", (DOCS_IMG / f"{stem}.png" if docs else None)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(
        prog="python -m benchmarks.segmentation", description=__doc__.split("\n")[0]
    )
    ap.add_argument("--json", action="store_true", help="print one JSON object on the last line")
    ap.add_argument(
        "--repeats", type=int, default=3, help="timed runs per method and image (median)"
    )
    ap.add_argument("--grid", action="store_true", help="rerun the parameter grids and print them")
    ap.add_argument("--no-figures", action="store_true", help="skip the PNG figures")
    ap.add_argument(
        "--docs",
        action="store_true",
        help="also refresh the README's small copies in docs/img/ (tracked files)",
    )
    ap.add_argument(
        "--providers",
        default=",".join(PROVIDERS),
        help=f"comma-separated image providers (default: {','.join(PROVIDERS)})",
    )
    args = ap.parse_args(argv)
    if args.docs and args.no_figures:
        ap.error("--docs refreshes the figures: drop --no-figures")
    if args.repeats < 1:
        ap.error(f"--repeats must be >= 1, got {args.repeats}")
    providers = [p.strip() for p in args.providers.split(",") if p.strip()]
    unknown = [p for p in providers if p not in PROVIDERS]
    if unknown or not providers:
        ap.error(f"--providers must name some of {', '.join(PROVIDERS)}, got {args.providers!r}")
    if args.grid and TUNING_PROVIDER not in providers:
        ap.error(f"--grid tunes on the {TUNING_PROVIDER!r} images: include that provider")
    console = Console(width=150)
    err = Console(stderr=True)
    with Progress(console=err, transient=True) as bar:
        task = bar.add_task("preparing cases (GrabCut references, wheel renders)", total=None)
        cases, skipped = all_cases(providers)
        for provider, reason in skipped.items():
            err.print(f"provider {provider!r} skipped: {reason}")
        if not cases:
            err.print("no benchmark images: every provider was skipped")
            return 1
        bar.update(task, description="warming up")
        _warm_up()
        if args.grid:
            grid = run_grid(cases, lambda m: bar.update(task, description=m))
        n_steps = 6 * len(cases)
        bar.update(task, total=n_steps, completed=0)

        def step(msg: str) -> None:
            bar.update(task, description=msg, advance=1)

        rows = run_benchmark(cases, args.repeats, step)
        if not args.no_figures:
            bar.update(task, description="figures")
            from benchmarks.segmentation_figures import comparison_figure, evolution_figure

            # (The wheel renders carry sensor noise, which PNG compresses badly: lower dpi.)
            for provider, stem, dpi in (
                ("skimage", "segmentation", 90),
                ("sim", "segmentation_wheels", 64),
            ):
                mine = [r for r in rows if r["case"].provider == provider]
                if mine:
                    comparison_figure(mine, *figure_paths(stem, docs=args.docs), dpi=dpi)
            if any(c.name == "coins" for c in cases):
                evolution_figure(cases, *figure_paths("levelset_evolution", docs=args.docs))
    summary = summarise(rows, skipped)
    if args.grid:
        for method, grid_rows in grid.items():
            t = Table(title=f"grid {method} (best first)")
            t.add_column("params")
            t.add_column("IoU per image")
            t.add_column("mean")
            t.add_column("s per image")
            for g in grid_rows:
                t.add_row(
                    json.dumps(g["params"]),
                    " ".join(f"{v:.3f}" for v in g["iou"]),
                    f"{g['mean_iou']:.4f}",
                    " ".join(f"{v:.3f}" for v in g["seconds"]),
                )
            console.print(t)
        summary["grid"] = grid
    print_table(summary, console)
    if not args.no_figures:
        console.print(f"figures: {', '.join(str(p) for p in sorted(OUT_DIR.glob('*.png')))}")
    if args.json:
        print(json.dumps(summary))
    return 0


if __name__ == "__main__":
    sys.exit(main())
