"""Benchmark of features and registration (issue 6; chapter sections 3.3-3.4, 4.2-4.3).

    python -m benchmarks.registration [--json] [--methods sift surf ...] [--quick]
                                      [--plots DIR] [--docs-img DIR] [--data-dir DIR]

Per method and sequence: extraction time per image, matching time (exact ratio test with
mutual check), recall at 1-precision = 0.1, area under the recall vs 1-precision curve and best
recall (Mikolajczyk and Schmid 2005, chapter eqs. 24-25; see ``vision.evaluation``). OpenCV SIFT
is the baseline measured in the same run (ratios vs SIFT). Sequences: Oxford graf, boat, bikes
(pairs 1-N), illumination changes of scikit-image photos, synthetic rescaling (Figure 12),
simulated wheel views (Figure 15/16) and real light changes seen by a fixed camera (issue 17:
MIMO lab scenes as 8-bit sRGB and as 16-bit linear RGB, SFU scenes as dark 8-bit linear RGB;
every lamp combination against a reference, identity geometry, see
``registration_data.real_illumination_pairs``). On the 16-bit set the grey methods and
OpponentSIFT see its 8-bit sRGB encoding, the colour methods the linear values; keypoints are
the same. Labels ``color-sift:chapter`` / ``color-surf:chapter`` are the chapter's layout (the
colour descriptor as first built), ``color-sift:srgb`` / ``color-surf:srgb`` linearise the
sRGB set before the ratios (run on the 8-bit sRGB set only). Every image is capped at ``--max-features`` strongest
keypoints (default 2000) for all methods alike; matching times are the best of 3 runs. Methods whose module is not importable are
skipped with the reason. Plots go to ``--plots`` (default ``var/bench/registration``).
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import sys
import time
from pathlib import Path
from typing import Any

os.environ.setdefault("MUJOCO_GL", "egl")

import cv2
import numpy as np
from rich.console import Console
from rich.table import Table

from benchmarks import registration_data as rd
from benchmarks import registration_figures as figs
from vision.evaluation import evaluate_pair
from vision.features import METHODS, extract
from vision.features.colour_input import srgb8_from_linear
from vision.registration import match, verify

REPO = Path(__file__).resolve().parents[1]
out = Console()
err = Console(stderr=True)
BASELINE = "sift"
COLOUR_BASE = {"color-sift": "sift", "color-surf": "surf"}
FULL_SUFFIX = ":full"
#: Label suffixes: the colour descriptor with other options, run beside the default one.
VARIANTS: dict[str, dict[str, Any]] = {
    FULL_SUFFIX: {"reduce": False},
    ":chapter": {"layout": "chapter"},
    ":srgb": {"transfer": "srgb"},
}
#: Variants that only make sense on some sets (sRGB linearisation on sRGB images).
VARIANT_SETS = {":srgb": ("mimo-srgb8",)}
REAL = rd.REAL_ILLUMINATION_SETS
DOCS_MAX_BYTES = 300_000  # README images stay small
WHITE = rd.MIMO_WHITE_LEVEL  # the only uint16 images are MIMO's
ALL_SEQUENCES = (
    *rd.OXFORD_SEQUENCES,
    "illumination",
    "scale",
    "sim-wheel",
    *rd.REAL_ILLUMINATION_SETS,
)


def _log(msg: str) -> None:
    err.print(f"[dim]{time.strftime('%H:%M:%S')}[/dim] {msg}")


def _spec(label: str) -> tuple[str, dict[str, Any]]:
    for suffix, opts in VARIANTS.items():
        if label.endswith(suffix):
            return label.removesuffix(suffix), dict(opts)
    return label, {}


def _suffix(label: str) -> str:
    return next((s for s in VARIANTS if label.endswith(s)), "")


def _extract(img: np.ndarray, method: str, max_features: int, opts: dict[str, Any]):
    """``extract`` as each method sees a pair's image: a uint16 (linear) image goes to the
    colour methods as it is, with the set's white level, and to the others as its 8-bit sRGB
    encoding (what the camera's 8-bit output shows; the colour methods detect on the same)."""
    if img.dtype == np.uint16:
        if method in COLOUR_BASE:
            return extract(img, method, max_features=max_features, white_level=WHITE, **opts)
        img = srgb8_from_linear(img, white_level=WHITE)
    return extract(img, method, max_features=max_features, **opts)


def available(label: str, max_features: int) -> str | None:
    """None when ``label`` extracts, else the reason it is skipped."""
    method, opts = _spec(label)
    probe = rd.skimage_photo("astronaut")[:128, :128].copy()
    try:
        extract(probe, method, max_features=max_features, **opts)
    except (ImportError, ModuleNotFoundError) as exc:
        return f"module not importable yet ({exc})"
    except TypeError as exc:
        return f"option not supported ({exc})"
    except Exception as exc:  # a broken method must not stop the benchmark
        return f"{type(exc).__name__}: {exc}"
    return None


def load_pairs(args: argparse.Namespace) -> tuple[list[rd.ImagePair], dict[str, str]]:
    quick = args.quick
    pairs: list[rd.ImagePair] = []
    skipped: dict[str, str] = {}
    wanted = set(args.sequences or ALL_SEQUENCES)
    for seq in ALL_SEQUENCES:
        if seq not in wanted:
            skipped[seq] = "not in --sequences"
    idx = {"graf": (2, 3), "boat": (3,), "bikes": (2,)} if quick else {}
    for seq in [q for q in rd.OXFORD_SEQUENCES if q in wanted]:
        try:
            pairs += rd.oxford_pairs(args.data_dir, seq, idx.get(seq, (2, 3, 4, 5, 6)))
        except FileNotFoundError as exc:
            skipped[seq] = str(exc)
    photos = rd.PHOTOS[:1] if quick else rd.PHOTOS
    if "illumination" in wanted:
        pairs += rd.illumination_pairs(photos, None if quick else args.data_dir)
    factors = (2.0, 3.0) if quick else (1.25, 1.5, 2.0, 2.5, 3.0, 3.5, 4.0)
    if "scale" in wanted:
        pairs += rd.scale_pairs(rd.skimage_photo("astronaut"), factors)
    real = tuple(s for s in rd.REAL_ILLUMINATION_SETS if s in wanted)
    if real:
        got, why = rd.real_illumination_pairs(args.data_dir, real)
        if quick:  # two scenes of each set
            keep = {(p.sequence, p.name.split("/")[0]) for p in got}
            first = {}
            for seq, scene in sorted(keep):
                first.setdefault(seq, []).append(scene)
            got = [p for p in got if p.name.split("/")[0] in first[p.sequence][:2]]
        pairs += got
        skipped.update(why)
    if "sim-wheel" not in wanted:
        pass
    elif quick and not args.sim:
        skipped["sim-wheel"] = "not in --quick (add --sim)"
    else:
        try:
            pairs += rd.sim_wheel_pairs()
        except Exception as exc:  # rendering needs EGL and MuJoCo
            skipped["sim-wheel"] = f"simulator unavailable: {type(exc).__name__}: {exc}"
    return pairs, skipped


def _thin(x: np.ndarray, n: int = 200) -> list[float]:
    if len(x) <= n:
        return [round(float(v), 4) for v in x]
    idx = np.unique(np.linspace(0, len(x) - 1, n).round().astype(int))
    return [round(float(v), 4) for v in x[idx]]


def run_method(
    label: str,
    pairs: list[rd.ImagePair],
    max_features: int,
    progress_prefix: str,
    match_repeats: int = 1,
) -> list[dict[str, Any]]:
    """Extract, match (best of ``match_repeats`` timings) and evaluate every pair."""
    method, opts = _spec(label)
    cache: dict[int, tuple[Any, float]] = {}
    only = VARIANT_SETS.get(_suffix(label))
    if only is not None:
        pairs = [p for p in pairs if p.sequence in only]

    def feats(img: np.ndarray) -> tuple[Any, float]:
        key = id(img)
        if key not in cache:
            t = time.perf_counter()
            f = _extract(img, method, max_features, opts)
            cache[key] = (f, time.perf_counter() - t)
        return cache[key]

    rows = []
    for k, p in enumerate(pairs):
        _log(f"{progress_prefix} {label}: {p.sequence} {p.name} ({k + 1}/{len(pairs)})")
        fa, ta = feats(p.a)
        fb, tb = feats(p.b)
        t_match = float("inf")
        for _ in range(match_repeats):
            t = time.perf_counter()
            if len(fa) and len(fb):
                match(fa, fb, ratio=0.8, mutual=True, method="exact")
            t_match = min(t_match, time.perf_counter() - t)
        ev = evaluate_pair(fa, fb, p.H, mask_a=p.mask_a)
        c = ev.curve
        rows.append(
            {
                "method": label,
                "sequence": p.sequence,
                "pair": p.name,
                "param": p.param,
                "n_a": len(fa),
                "n_b": len(fb),
                "extract_ms": 1e3 * (ta + tb) / 2.0,
                "match_ms": 1e3 * t_match,
                "n_correspondences": ev.n_correspondences,
                "recall_at_01": ev.recall_at_01,
                "auc": ev.auc,
                "best_recall": ev.best_recall,
                "curve_1mp": _thin(c.one_minus_precision),
                "curve_recall": _thin(c.recall),
            }
        )
    return rows


def _pair_640(data_dir: Path) -> tuple[np.ndarray, np.ndarray, str]:
    try:
        p = rd.oxford_pairs(data_dir, "graf", (2,))[0]
        a, b, src = p.a, p.b, "graf img1/img2 resized to 640x480"
    except FileNotFoundError:
        a = rd.skimage_photo("astronaut")
        H = rd.similarity_about_centre(a.shape[:2], 10.0, 0.9)
        b = cv2.warpPerspective(a, H, (a.shape[1], a.shape[0]))
        src = "astronaut and a 10 deg / 0.9 warp, resized to 640x480"
    return cv2.resize(a, (640, 480)), cv2.resize(b, (640, 480)), src


def timing_640(methods: list[str], data_dir: Path, repeats: int) -> dict[str, Any]:
    """Per method: extraction ms of a 640x480 image and extract+match+verify ms of a pair,
    the best of ``repeats``. The methods take turns within each repeat, so a burst of load
    on the shared machine hits every method alike and the ratios stay fair."""
    a, b, src = _pair_640(data_dir)
    res: dict[str, Any] = {"source": src}
    ext: dict[str, list[float]] = {m: [] for m in methods}
    full: dict[str, list[float]] = {m: [] for m in methods}
    n: dict[str, int] = {}
    for _ in range(repeats):
        for label in methods:
            method, opts = _spec(label)
            t0 = time.perf_counter()
            fa = extract(a, method, **opts)
            t1 = time.perf_counter()
            fb = extract(b, method, **opts)
            m = match(fa, fb)
            verify(m, fa, fb)
            t2 = time.perf_counter()
            ext[label].append(t1 - t0)
            full[label].append(t2 - t0)
            n[label] = len(fa)
    for label in methods:
        res[label] = {
            "extract_ms": 1e3 * min(ext[label]),
            "extract_ms_median": 1e3 * float(np.median(ext[label])),
            "pair_ms": 1e3 * min(full[label]),
            "n": n[label],
        }
    return res


def summarise(rows: list[dict[str, Any]]) -> dict[str, dict[str, dict[str, float]]]:
    summary: dict[str, dict[str, dict[str, float]]] = {}
    for r in rows:
        s = summary.setdefault(r["method"], {}).setdefault(r["sequence"], {})
        for k in ("recall_at_01", "auc", "best_recall", "extract_ms", "match_ms"):
            s.setdefault(k, 0.0)
            s[k] += r[k]
        s["n"] = s.get("n", 0) + 1
    for seqs in summary.values():
        for s in seqs.values():
            for k in ("recall_at_01", "auc", "best_recall", "extract_ms", "match_ms"):
                s[k] /= s["n"]
    for label, seqs in summary.items():
        grey = COLOUR_BASE.get(_spec(label)[0])
        for seq, s in seqs.items():
            g = summary.get(grey, {}).get(seq) if grey else None
            if g and g["recall_at_01"]:
                s["recall_vs_base"] = s["recall_at_01"] / g["recall_at_01"]
                s["extract_vs_base"] = s["extract_ms"] / g["extract_ms"]
    base = summary.get(BASELINE, {})
    for seqs in summary.values():
        for seq, s in seqs.items():
            b = base.get(seq)
            if b:
                s["recall_vs_sift"] = (
                    s["recall_at_01"] / b["recall_at_01"] if b["recall_at_01"] else float("nan")
                )
                s["extract_vs_sift"] = s["extract_ms"] / b["extract_ms"]
                s["match_vs_sift"] = (
                    s["match_ms"] / b["match_ms"] if b["match_ms"] else float("nan")
                )
    return summary


def _held_out(rows: list[dict[str, Any]], colour: str, grey: str) -> tuple[float, float] | None:
    """Mean recall@0.1 of the two methods on the illumination pairs of the Oxford images,
    which the colour PCA bases never saw (the scikit-image photos are training images)."""
    out = []
    for m in (colour, grey):
        r = [
            x["recall_at_01"]
            for x in rows
            if x["method"] == m
            and x["sequence"] == "illumination"
            and x["pair"].startswith("oxford-")
        ]
        if not r:
            return None
        out.append(float(np.mean(r)))
    return out[0], out[1]


def real_comparison(rows: list[dict[str, Any]], colour: str, grey: str) -> dict[str, Any]:
    """Per-pair comparison of a colour label with its grey base on the real illumination sets:
    mean recall@0.1 of both, the share of pairs where the colour one is >= the grey one, per
    set and over all real pairs."""
    g = {(r["sequence"], r["pair"]): r["recall_at_01"] for r in rows if r["method"] == grey}
    out: dict[str, Any] = {}
    for seq in (*REAL, "all"):
        c = [
            (r["recall_at_01"], g[(r["sequence"], r["pair"])])
            for r in rows
            if r["method"] == colour
            and (r["sequence"] == seq or (seq == "all" and r["sequence"] in REAL))
            and (r["sequence"], r["pair"]) in g
        ]
        if c:
            a = np.array(c)
            out[seq] = {
                "pairs": len(a),
                "colour": float(a[:, 0].mean()),
                "grey": float(a[:, 1].mean()),
                "share_ge": float((a[:, 0] >= a[:, 1]).mean()),
            }
    return out


def real_targets(rows, timing) -> list[dict[str, Any]]:
    """Issue 17: the colour descriptor >= its grey base on the real illumination pairs (mean,
    and on >= 80 % of the pairs); extraction <= 2x the grey base's (640x480)."""
    out_t = []
    for colour, grey in COLOUR_BASE.items():
        cmp = real_comparison(rows, colour, grey)
        if "all" not in cmp:
            out_t.append(_target(f"{colour} vs {grey} on real light changes", None, "not run"))
        for seq, c in cmp.items():
            where = "all real pairs" if seq == "all" else seq
            out_t.append(
                _target(
                    f"{colour} recall@0.1 >= {grey} on {where} (mean)",
                    c["colour"] >= c["grey"],
                    f"{c['colour']:.3f} vs {c['grey']:.3f} ({c['pairs']} pairs)",
                )
            )
            out_t.append(
                _target(
                    f"{colour} >= {grey} on >= 80 % of {where}",
                    c["share_ge"] >= 0.8,
                    f"{100 * c['share_ge']:.0f} % of {c['pairs']} pairs",
                )
            )
        if colour in timing and grey in timing:
            r = timing[colour]["extract_ms"] / timing[grey]["extract_ms"]
            out_t.append(
                _target(
                    f"{colour} extraction <= 2x {grey} (640x480)",
                    r <= 2.0,
                    f"{r:.2f}x ({timing[colour]['extract_ms']:.0f} vs {timing[grey]['extract_ms']:.0f} ms)",
                )
            )
    return out_t


def _target(name: str, ok: bool | None, figure: str) -> dict[str, Any]:
    status = "SKIP" if ok is None else ("PASS" if ok else "MISS")
    return {"target": name, "status": status, "figure": figure}


def targets(rows, summary, timing, labels) -> list[dict[str, Any]]:
    out_t = []
    for colour, grey in COLOUR_BASE.items():
        if colour not in summary or grey not in summary:
            out_t.append(_target(f"{colour} vs {grey}", None, "method not run"))
            continue
        c, g = summary[colour], summary[grey]
        if "illumination" in c:
            rc, rg = c["illumination"]["recall_at_01"], g["illumination"]["recall_at_01"]
            out_t.append(
                _target(
                    f"{colour} recall@0.1 >= {grey} on illumination",
                    rc >= rg,
                    f"{rc:.3f} vs {rg:.3f}",
                )
            )
            held = _held_out(rows, colour, grey)
            if held is not None:
                rc, rg = held
                out_t.append(
                    _target(
                        f"{colour} recall@0.1 >= {grey} on illumination, held-out images",
                        rc >= rg,
                        f"{rc:.3f} vs {rg:.3f} (Oxford graf/bikes img1)",
                    )
                )
        for seq in rd.OXFORD_SEQUENCES:
            if seq in c:
                rc, rg = c[seq]["recall_at_01"], g[seq]["recall_at_01"]
                out_t.append(
                    _target(
                        f"{colour} recall@0.1 >= 95 % of {grey} on {seq}",
                        rc >= 0.95 * rg,
                        f"{rc:.3f} vs {rg:.3f} ({100 * (rc / rg - 1) if rg else float('nan'):+.1f} %)",
                    )
                )
    for colour in COLOUR_BASE:
        full = colour + FULL_SUFFIX
        if colour in summary and full in summary:
            red = [r for r in rows if r["method"] == colour]
            fr = [r for r in rows if r["method"] == full]
            t_red = np.mean([r["match_ms"] for r in red])
            t_full = np.mean([r["match_ms"] for r in fr])
            r_red = np.mean([r["recall_at_01"] for r in red])
            r_full = np.mean([r["recall_at_01"] for r in fr])
            speed = t_full / t_red if t_red else float("nan")
            loss = (r_full - r_red) / r_full if r_full else float("nan")
            out_t.append(
                _target(
                    f"{colour} PCA: matching >= 2x faster than reduce=False",
                    speed >= 2.0,
                    f"{speed:.2f}x ({t_red:.1f} vs {t_full:.1f} ms)",
                )
            )
            out_t.append(
                _target(
                    f"{colour} PCA: recall loss <= 5 %",
                    loss <= 0.05,
                    f"{100 * loss:.1f} % ({r_red:.3f} vs {r_full:.3f})",
                )
            )
        else:
            out_t.append(_target(f"{colour} PCA reduction", None, "method or reduce=False not run"))
    if "surf" in summary and BASELINE in summary:
        for seq, pair in (("graf", "1-3"), ("boat", "1-3")):
            s = [
                r
                for r in rows
                if r["method"] == "surf" and r["sequence"] == seq and r["pair"] == pair
            ]
            b = [
                r
                for r in rows
                if r["method"] == BASELINE and r["sequence"] == seq and r["pair"] == pair
            ]
            if s and b:
                rs, rb = s[0]["recall_at_01"], b[0]["recall_at_01"]
                out_t.append(
                    _target(
                        f"surf recall@0.1 within 10 % of sift on {seq} {pair}",
                        rs >= 0.9 * rb,
                        f"{rs:.3f} vs {rb:.3f}",
                    )
                )
    if "surf" in timing:
        ms = timing["surf"]["extract_ms"]
        out_t.append(_target("surf extraction <= 150 ms (640x480)", ms <= 150.0, f"{ms:.0f} ms"))
    else:
        out_t.append(_target("surf extraction <= 150 ms (640x480)", None, "surf not run"))
    if BASELINE in timing:
        ms = timing[BASELINE]["pair_ms"]
        out_t.append(
            _target("sift extract+match+verify <= 80 ms (640x480 pair)", ms <= 80.0, f"{ms:.0f} ms")
        )
    del labels
    return out_t + real_targets(rows, timing)


def _no_nan(v: Any) -> Any:
    """NaN and inf become null so that the JSON line is strict JSON."""
    if isinstance(v, float | np.floating):
        return float(v) if np.isfinite(v) else None
    if isinstance(v, dict):
        return {k: _no_nan(x) for k, x in v.items()}
    if isinstance(v, list | tuple):
        return [_no_nan(x) for x in v]
    return v


def _f(v: float, nd: int = 3) -> str:
    return "-" if v is None or not np.isfinite(v) else f"{v:.{nd}f}"


def write_plots(rows, labels, pairs, plot_dir: Path, docs_img: Path | None) -> list[str]:
    grey = [m for m in labels if not m.endswith(FULL_SUFFIX)]
    sim = [p for p in pairs if p.sequence == "sim-wheel"]
    paths = [
        figs.figure_pairs(sim, plot_dir / "fig15_sim_wheel.png"),
        figs.figure_scale(rows, grey, plot_dir / "fig12_scale.png"),
        figs.figure_viewpoint(rows, grey, plot_dir / "fig14_viewpoint.png"),
        figs.figure_colour(
            rows,
            [(c, g) for c, g in COLOUR_BASE.items() if c in labels and g in labels],
            plot_dir / "fig16_colour.png",
        ),
    ]
    for seq in (*rd.OXFORD_SEQUENCES, "illumination", "sim-wheel"):
        paths.append(figs.figure_sequence(rows, grey, seq, plot_dir / f"recall_{seq}.png"))
    pairs_real = [(c, COLOUR_BASE[_spec(c)[0]]) for c in labels if _spec(c)[0] in COLOUR_BASE]
    paths.append(figs.figure_real(rows, pairs_real, REAL, plot_dir / "real_illumination.png"))
    paths = [p for p in paths if p is not None]
    if docs_img is not None:
        docs_img.mkdir(parents=True, exist_ok=True)
        for p in paths:
            if p.stat().st_size > DOCS_MAX_BYTES:
                err.print(f"not copying {p.name} to {docs_img}: over {DOCS_MAX_BYTES} bytes")
                continue
            shutil.copyfile(p, docs_img / f"registration_{p.name}")
    return [str(p) for p in paths]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--json", action="store_true", help="print one JSON object on the last line")
    ap.add_argument("--methods", nargs="+", default=list(METHODS), help="feature methods")
    ap.add_argument("--quick", action="store_true", help="a few pairs only (smoke test)")
    ap.add_argument(
        "--sequences", nargs="+", choices=ALL_SEQUENCES, default=None, help="default: all"
    )
    ap.add_argument("--sim", action="store_true", help="include the simulated wheels in --quick")
    ap.add_argument("--data-dir", type=Path, default=REPO.parent / "shared" / "data")
    ap.add_argument("--plots", type=Path, default=REPO / "var" / "bench" / "registration")
    ap.add_argument("--docs-img", type=Path, default=None, help="also copy the plots here")
    ap.add_argument(
        "--docs", action="store_true", help="refresh the README's plots (= --docs-img docs/img)"
    )
    ap.add_argument("--max-features", type=int, default=2000)
    ap.add_argument("--no-plots", action="store_true")
    ap.add_argument(
        "--no-variants",
        action="store_true",
        help="skip the colour descriptor's :chapter and :srgb variants",
    )
    ap.add_argument(
        "--no-full", action="store_true", help="skip the colour descriptor's :full variant"
    )
    args = ap.parse_args(argv)
    if args.docs and args.docs_img is None:
        args.docs_img = REPO / "docs" / "img"

    unknown = [m for m in args.methods if _spec(m)[0] not in METHODS]
    if unknown:
        ap.error(f"unknown methods {unknown}; choose from {', '.join(METHODS)}")
    labels = list(dict.fromkeys([BASELINE, *args.methods]))
    if not args.no_full:
        labels += [c + FULL_SUFFIX for c in COLOUR_BASE if c in labels]
    if not args.no_variants:
        labels += [c + v for v in (":chapter", ":srgb") for c in COLOUR_BASE if c in labels]
    skipped: dict[str, str] = {}
    run: list[str] = []
    for label in labels:
        why = available(label, args.max_features)
        if why:
            skipped[label] = why
            err.print(f"skipping {label}: {why}")
        else:
            run.append(label)
    pairs, skipped_seq = load_pairs(args)
    for seq, why in skipped_seq.items():
        err.print(f"skipping sequence {seq}: {why}")
    rows: list[dict[str, Any]] = []
    for i, label in enumerate(run):
        rows += run_method(
            label, pairs, args.max_features, f"[{i + 1}/{len(run)}]", 1 if args.quick else 3
        )
    _log("timing 640x480")
    timing = timing_640(run, args.data_dir, 1 if args.quick else 5)
    summary = summarise(rows)
    tgt = targets(rows, summary, timing, run)

    t = Table(title="Registration: mean per sequence (recall@0.1 = recall at 1-precision 0.1)")
    for col in (
        "method",
        "sequence",
        "pairs",
        "extract ms",
        "match ms",
        "recall@0.1",
        "AUC",
        "best recall",
        "recall/SIFT",
        "extract/SIFT",
        "recall/base",
    ):
        t.add_column(col, justify="left" if col in ("method", "sequence") else "right")
    for m, seqs in summary.items():
        for seq, s in seqs.items():
            t.add_row(
                m,
                seq,
                str(s["n"]),
                _f(s["extract_ms"], 1),
                _f(s["match_ms"], 2),
                _f(s["recall_at_01"]),
                _f(s["auc"]),
                _f(s["best_recall"]),
                _f(s.get("recall_vs_sift", float("nan")), 2),
                _f(s.get("extract_vs_sift", float("nan")), 2),
                _f(s.get("recall_vs_base", float("nan")), 2),
            )
    out.print(t)
    t2 = Table(title=f"640x480 timing ({timing['source']})")
    for col in ("method", "extract ms", "extract+match+verify pair ms", "features"):
        t2.add_column(col, justify="left" if col == "method" else "right")
    for m in run:
        t2.add_row(
            m, _f(timing[m]["extract_ms"], 1), _f(timing[m]["pair_ms"], 1), str(timing[m]["n"])
        )
    out.print(t2)
    t3 = Table(title="Targets (issues 6 and 17)")
    for col in ("target", "status", "figure"):
        t3.add_column(col)
    for x in tgt:
        t3.add_row(x["target"], x["status"], x["figure"])
    out.print(t3)
    plots = [] if args.no_plots else write_plots(rows, run, pairs, args.plots, args.docs_img)
    if plots:
        out.print(f"plots: {', '.join(plots)}")
    if args.json:
        result = {
            "methods": run,
            "skipped": skipped,
            "skipped_sequences": skipped_seq,
            "baseline": BASELINE,
            "max_features": args.max_features,
            "summary": summary,
            "timing_640": timing,
            "targets": tgt,
            "real_illumination": {
                lab: real_comparison(rows, lab, COLOUR_BASE.get(_spec(lab)[0], BASELINE))
                for lab in run
                if lab not in COLOUR_BASE.values()
            },
            "plots": plots,
            "rows": [{k: v for k, v in r.items() if not k.startswith("curve")} for r in rows],
        }
        print(json.dumps(_no_nan(result), default=float))
    return 0


if __name__ == "__main__":
    sys.exit(main())
