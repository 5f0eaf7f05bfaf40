"""Inverse-kinematics benchmark: closed form, hybrid (3.6.1), Sugeno fuzzy (3.6.3), ikpy.

    python -m benchmarks.kinematics [--json] [--n 100000] [--ikpy-n 300] [--quick]

Poses: ``n`` random reachable poses made by drawing q1..q5 uniformly within the joint ranges
(seeded) and applying eq. 20; the roll is the drawn q5.  Every solver sees the same poses
(ikpy a seeded random subset of ``--ikpy-n``, being milliseconds per pose).  Errors are those
of FK(IK(p)) against p: position in metres and approach angle ``phi`` in radians; "success"
means a solution within the joint ranges with both errors at or below 1e-6.

The fuzzy system is tuned by the chapter's protocol (section 4.4: 100 training poses, 50
test poses, 50 GA cycles) on the inspection-station viewing region and on the whole
workspace, then evaluated on ``n`` poses of its region.  Figures (PNG) and the tuned systems
(``.npz``) go to ``benchmarks/out/``.  Progress goes to stderr; with ``--json`` the last line
of stdout is one JSON object.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import tempfile
import time
import warnings
from pathlib import Path
from typing import Any

import numpy as np
from rich.console import Console
from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn
from rich.table import Table

from robot.kinematics import fk, hybrid_ik, hybrid_ik_batch, ik, ik_batch
from robot.kinematics.fuzzy_ga import GAConfig
from robot.kinematics.fuzzy_protocol import (
    CHAPTER,
    STATION_REGION,
    WORKSPACE_REGION,
    ProtocolReport,
    run_chapter_protocol,
    sample_poses,
)
from robot.kinematics.hybrid import fuzzy_estimator
from robot.model import ASEA
from robot.urdf import urdf_from_model

OUT = Path(__file__).resolve().parent / "out"
SUCCESS_TOL = 1e-6
TARGETS = {
    "analytic_success_rate": 1.0,
    "analytic_max_position_error_m": 1e-9,
    "analytic_median_single_us": 10.0,
    "analytic_batched_poses_per_s": 2e6,
    "speedup_vs_chapter": 50.0,
    "speedup_vs_ikpy": 100.0,
}


def _errors(q: np.ndarray, poses: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Position and approach-angle errors of FK(q) against poses; NaN rows count as failures."""
    ok_rows = np.all(np.isfinite(q), axis=1)
    ep = np.full(len(q), np.inf)
    ea = np.full(len(q), np.inf)
    a = fk(q[ok_rows])
    ep[ok_rows] = np.linalg.norm(a[:, :3] - poses[ok_rows, :3], axis=1)
    dphi = np.arctan2(a[:, 4], a[:, 3]) - np.arctan2(poses[ok_rows, 4], poses[ok_rows, 3])
    ea[ok_rows] = np.abs(np.angle(np.exp(1j * dphi)))
    within = np.zeros(len(q), dtype=bool)
    within[ok_rows] = ASEA.within_limits(q[ok_rows])
    return ep, ea, within


def _summary(name: str, q: np.ndarray, poses: np.ndarray, **extra: Any) -> dict[str, Any]:
    ep, ea, within = _errors(q, poses)
    success = within & (ep <= SUCCESS_TOL) & (ea <= SUCCESS_TOL)
    fin = np.isfinite(ep)
    return {
        "method": name,
        "poses": len(q),
        "success_rate": float(success.mean()),
        "within_limits_rate": float(within.mean()),
        "max_position_error_m": float(ep[fin].max()) if fin.any() else math.inf,
        "median_position_error_m": float(np.median(ep[fin])) if fin.any() else math.inf,
        "max_angle_error_rad": float(ea[fin].max()) if fin.any() else math.inf,
        **extra,
    }


def _single_latency_s(fn, items: list, progress=None) -> float:
    times = np.empty(len(items))
    step = max(1, len(items) // 50)
    for i, it in enumerate(items):
        t0 = time.perf_counter_ns()
        fn(it)
        times[i] = time.perf_counter_ns() - t0
        if progress is not None and i % step == 0:
            progress(i / len(items))
    return float(np.median(times)) * 1e-9


def _best_of(fn, repeats: int) -> float:
    best = math.inf
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


def run(n: int, ikpy_n: int, seed: int, ga_cycles: int, progress: Progress) -> dict[str, Any]:
    """Run every measurement; returns the JSON-able results."""
    rng = np.random.default_rng(seed)
    q_true = rng.uniform(ASEA.lower, ASEA.upper, size=(n, 5))
    poses = fk(q_true)
    rolls = q_true[:, 4].copy()
    rows: list[dict[str, Any]] = []
    task = progress.add_task("analytic IK, single poses", total=1.0)

    # Closed form, one pose per call (floats in, as the backend passes them).
    items = list(zip(poses.tolist(), rolls.tolist(), strict=True))
    q_single = np.empty((n, 5))

    def one(it: tuple[list[float], float], out=q_single, idx=iter(range(n))) -> None:
        out[next(idx)] = ik(it[0], roll=it[1])

    lat = _single_latency_s(one, items, lambda f: progress.update(task, completed=f))
    # As the backend calls it: numpy pose and the current joints as the seed.
    seeded = [(poses[i], float(rolls[i]), q_true[i]) for i in range(min(n, 20_000))]
    lat_seeded = _single_latency_s(lambda it: ik(it[0], roll=it[1], seed=it[2]), seeded)
    progress.update(task, completed=1.0, description="analytic IK, batched")
    q_b, ok_b = ik_batch(poses, rolls)
    t_batch = _best_of(lambda: ik_batch(poses, rolls), 5)
    rot_err = _roll_aware_error(q_b[ok_b], q_true[ok_b])
    rows.append(
        _summary(
            "analytic (closed form)",
            q_b,
            poses,
            median_single_s=lat,
            median_single_numpy_seeded_s=lat_seeded,
            batched_poses_per_s=n / t_batch,
            scalar_equals_batch=bool(np.allclose(q_single, q_b, atol=1e-12, equal_nan=True)),
            max_rotation_error_incl_roll_rad=rot_err,
        )
    )

    # Hybrid loop, nominal-model estimator.
    progress.update(task, description="hybrid IK (3.6.1), batched")
    t0 = time.perf_counter()
    hb = hybrid_ik_batch(poses, rolls)
    t_h = time.perf_counter() - t0
    sub = rng.choice(n, size=min(n, 1000), replace=False)
    lat_h = _single_latency_s(
        lambda i: hybrid_ik(poses[i], roll=float(rolls[i])), list(sub.tolist())
    )
    rows.append(
        _summary(
            "hybrid 3.6.1 (nominal-model estimate + FK loop)",
            np.where(hb.converged[:, None], hb.q, np.nan),
            poses,
            median_single_s=lat_h,
            batched_poses_per_s=n / t_h,
            mean_iterations=float(hb.iterations.mean()),
            max_iterations=int(hb.iterations.max()),
        )
    )

    # Sugeno fuzzy system: the chapter's protocol on two regions.
    reports: list[ProtocolReport] = []
    cfg = GAConfig(generations=ga_cycles)
    for region in (STATION_REGION, WORKSPACE_REGION):
        t = progress.add_task(f"SFIS protocol, {region.name}", total=1.0)
        rep = run_chapter_protocol(
            region, config=cfg, progress=lambda f, m, t=t: progress.update(t, completed=f)
        )
        reports.append(rep)
    fuzzy_rows, fuzzy_extra = _fuzzy_rows(reports, poses, rolls, n, seed)
    rows.extend(fuzzy_rows)

    # ikpy on a subset, same URDF-described arm.
    ik_rows, ikpy_time = _ikpy(poses, rolls, ikpy_n, seed, progress)
    rows.extend(ik_rows)

    analytic = rows[0]
    for r in rows:
        r["speedup_vs_chapter_0_8ms"] = CHAPTER.inference_s / r["median_single_s"]
        r["speedup_vs_ikpy"] = ikpy_time / r["median_single_s"]
        r["analytic_speedup"] = r["median_single_s"] / analytic["median_single_s"]
    result: dict[str, Any] = {
        "benchmark": "kinematics",
        "poses": n,
        "pose_sampling": "q1..q5 uniform within the joint ranges (seed "
        f"{seed}), pose = eq. 20, roll = q5",
        "success_tolerance": SUCCESS_TOL,
        "methods": rows,
        "sfis_protocol": [_protocol_dict(r) for r in reports],
        "sfis_extra": fuzzy_extra,
        "chapter": {
            "sse_before": CHAPTER.sse_before,
            "sse_after": CHAPTER.sse_after,
            "test_sse_per_pose_max": CHAPTER.test_sse_per_pose_max,
            "inference_s": CHAPTER.inference_s,
        },
        "ikpy_median_single_s": ikpy_time,
    }
    result["targets"] = _targets(analytic, ikpy_time)
    result["figures"] = _figures(reports)
    return result


def _roll_aware_error(q: np.ndarray, q_true: np.ndarray) -> float:
    from robot.kinematics import R_base_ee

    R = R_base_ee(q)
    Rt = R_base_ee(q_true)
    tr = np.einsum("nij,nij->n", R, Rt)
    return float(np.arccos(np.clip((tr - 1) / 2, -1, 1)).max())


def _fuzzy_rows(
    reports: list[ProtocolReport], poses: np.ndarray, rolls: np.ndarray, n: int, seed: int
) -> tuple[list[dict[str, Any]], dict[str, Any]]:
    rows = []
    station, workspace = reports
    rng = np.random.default_rng(seed + 1)
    Xs, _ = sample_poses(STATION_REGION, n, rng)
    extra: dict[str, Any] = {}
    for rep, X, label in (
        (station, Xs, "SFIS tuned on the station region, station poses"),
        (workspace, poses, "SFIS tuned on the whole workspace, workspace poses"),
        (station, poses, "SFIS tuned on the station region, workspace poses"),
    ):
        fis = rep.fis
        t_b = _best_of(lambda fis=fis, X=X: fis.infer(X), 3)
        lat = _single_latency_s(lambda i, fis=fis, X=X: fis.infer(X[i]), list(range(500)))
        q_hat = fis.infer(X)
        rows.append(
            _summary(label, q_hat, X, median_single_s=lat, batched_poses_per_s=len(X) / t_b)
        )
    # The chapter's combination: the fuzzy estimate corrected by the hybrid loop.
    for gain in (1.0, 0.5):
        t0 = time.perf_counter()
        hb = hybrid_ik_batch(Xs, 0.0, estimator=fuzzy_estimator(station.fis), gain=gain)
        dt = time.perf_counter() - t0
        extra[f"hybrid_fuzzy_station_gain_{gain}"] = {
            "converged_rate": float(hb.converged.mean()),
            "converged_within_limits_rate": float((hb.converged & hb.within_limits).mean()),
            "mean_iterations": float(hb.iterations.mean()),
            "poses_per_s": n / dt,
        }
    return rows, extra


def _ikpy(
    poses: np.ndarray, rolls: np.ndarray, k: int, seed: int, progress: Progress
) -> tuple[list[dict[str, Any]], float]:
    try:
        import ikpy.chain
    except ImportError:  # pragma: no cover - bench extra missing
        return [], math.nan
    with tempfile.TemporaryDirectory() as d, warnings.catch_warnings():
        warnings.simplefilter("ignore")
        path = Path(d) / "asea.urdf"
        path.write_text(urdf_from_model(ASEA))
        chain = ikpy.chain.Chain.from_urdf_file(
            str(path), base_elements=["base_link"], active_links_mask=[False] + [True] * 5
        )
    idx = np.random.default_rng(seed + 2).choice(len(poses), size=min(k, len(poses)), replace=False)
    task = progress.add_task(f"ikpy on {len(idx)} poses", total=len(idx))
    q = np.empty((len(idx), 5))
    times = np.empty(len(idx))
    init = [0.0, *ASEA.q_home]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for j, i in enumerate(idx):
            x, y, z, u, w = poses[i]
            th = math.atan2(y, x)
            approach = np.array([u * math.cos(th), u * math.sin(th), w])
            t0 = time.perf_counter_ns()
            sol = chain.inverse_kinematics(
                [x, y, z], approach, orientation_mode="Z", initial_position=init
            )
            times[j] = time.perf_counter_ns() - t0
            q[j] = sol[1:]
            q[j, 4] = rolls[i]  # the roll is not part of ikpy's "Z" target
            progress.update(task, advance=1)
    lat = float(np.median(times)) * 1e-9
    row = _summary(
        f"ikpy {getattr(ikpy, '__version__', '?')} (numeric, same URDF, subset)",
        q,
        poses[idx],
        median_single_s=lat,
        batched_poses_per_s=1.0 / float(np.mean(times) * 1e-9),
        within_1mm_rate=float((_errors(q, poses[idx])[0] <= 1e-3).mean()),
    )
    return [row], lat


def _protocol_dict(rep: ProtocolReport) -> dict[str, Any]:
    return {
        "region": rep.region.describe(),
        "n_train": rep.n_train,
        "n_test": rep.n_test,
        "ga_cycles": rep.ga.config.generations,
        "gd_learning_rate": rep.gd_learning_rate,
        "sse_untuned": rep.sse_untuned,
        "sse_consequents_only": rep.sse_consequents_only,
        "sse_tuned": rep.sse_tuned,
        "sse_tuned_per_pose": rep.sse_tuned / rep.n_train,
        "sse_untuned_per_pose": rep.sse_untuned / rep.n_train,
        "sse_tuned_least_squares": rep.sse_tuned_least_squares,
        "test_sse_per_pose_min": float(rep.test_sse_per_pose.min()),
        "test_sse_per_pose_max": float(rep.test_sse_per_pose.max()),
        "test_sse_per_pose_median": float(np.median(rep.test_sse_per_pose)),
        "test_position_error_max_m": float(rep.test_position_error_m.max()),
        "inference_s": rep.inference_s,
    }


def _targets(analytic: dict[str, Any], ikpy_s: float) -> dict[str, dict[str, Any]]:
    got = {
        "analytic_success_rate": analytic["success_rate"],
        "analytic_max_position_error_m": analytic["max_position_error_m"],
        "analytic_median_single_us": analytic["median_single_s"] * 1e6,
        "analytic_batched_poses_per_s": analytic["batched_poses_per_s"],
        "speedup_vs_chapter": CHAPTER.inference_s / analytic["median_single_s"],
        "speedup_vs_ikpy": ikpy_s / analytic["median_single_s"],
    }
    out = {}
    for k, target in TARGETS.items():
        v = got[k]
        lower_is_better = k in ("analytic_max_position_error_m", "analytic_median_single_us")
        met = v <= target if lower_is_better else v >= target
        out[k] = {"value": v, "target": target, "met": bool(met)}
    return out


def _figures(reports: list[ProtocolReport]) -> list[str]:
    from benchmarks.kinematics_figures import (
        plot_figure9_mfs,
        plot_figure17_sse,
        plot_ga_convergence,
    )

    OUT.mkdir(parents=True, exist_ok=True)
    paths = [
        plot_figure17_sse(reports, OUT / "kinematics_fig17_sse_per_test_pose.png"),
        plot_figure9_mfs(reports[0], OUT / "kinematics_fig9_tuned_mfs_station.png"),
        plot_ga_convergence(reports, OUT / "kinematics_ga_convergence.png"),
        reports[0].fis.save(OUT / "sfis_station.npz"),
        reports[1].fis.save(OUT / "sfis_workspace.npz"),
    ]
    return [str(p) for p in paths]


def _fmt_s(s: float) -> str:
    return f"{s * 1e6:.2f} us" if s < 1e-3 else f"{s * 1e3:.2f} ms"


def print_tables(res: dict[str, Any], console: Console) -> None:
    """The readable report."""
    t = Table(title=f"Inverse kinematics on {res['poses']:,} random reachable poses")
    for col in (
        "method",
        "poses",
        "success",
        "max pos err (m)",
        "max phi err (rad)",
        "median single",
        "batched (poses/s)",
        "vs chapter 0.8 ms",
        "vs ikpy",
    ):
        t.add_column(col, justify="left" if col == "method" else "right")
    for r in res["methods"]:
        t.add_row(
            r["method"],
            f"{r['poses']:,}",
            f"{100 * r['success_rate']:.2f} %",
            f"{r['max_position_error_m']:.2e}",
            f"{r['max_angle_error_rad']:.2e}",
            _fmt_s(r["median_single_s"]),
            f"{r['batched_poses_per_s']:,.0f}",
            f"{r['speedup_vs_chapter_0_8ms']:.1f}x",
            f"{r['speedup_vs_ikpy']:,.0f}x",
        )
    console.print(t)
    a = res["methods"][0]
    console.print(
        "speed ratios are of median single-pose times; closed form with a numpy pose and "
        f"the current joints as seed: {_fmt_s(a['median_single_numpy_seeded_s'])}"
    )
    p = Table(title="Chapter section 4.4 protocol (SSE in rad^2 over the five joints)")
    for col in ("quantity", *(d["region"].split(":")[0] for d in res["sfis_protocol"]), "chapter"):
        p.add_column(col, justify="right")
    ch = res["chapter"]
    pr = res["sfis_protocol"]

    def row(label: str, key: str, chapter: str, fmt: str = "{:.4g}") -> None:
        p.add_row(label, *(fmt.format(d[key]) for d in pr), chapter)

    row("training SSE, untuned (total over 100)", "sse_untuned", f"{ch['sse_before']}")
    row("  per pose", "sse_untuned_per_pose", "")
    row("training SSE, consequents (GD) only", "sse_consequents_only", "")
    row("training SSE after GA + GD (total)", "sse_tuned", f"{ch['sse_after']}")
    row("  per pose", "sse_tuned_per_pose", "")
    row("  least-squares consequents (reference)", "sse_tuned_least_squares", "")
    row(
        "test SSE per pose, max (50 poses)",
        "test_sse_per_pose_max",
        f"{ch['test_sse_per_pose_max']}",
    )
    row("test SSE per pose, median", "test_sse_per_pose_median", "")
    row("test flange position error, max (m)", "test_position_error_max_m", "")
    p.add_row(
        "inference time per pose",
        *(_fmt_s(d["inference_s"]) for d in pr),
        "< 0.8 ms",
    )
    console.print(p)
    for k, v in res["sfis_extra"].items():
        console.print(
            f"{k}: converged {100 * v['converged_rate']:.1f} % "
            f"(within limits {100 * v['converged_within_limits_rate']:.1f} %), "
            f"mean iterations {v['mean_iterations']:.1f}"
        )
    for k, v in res["targets"].items():
        console.print(
            f"target {k}: {v['value']:.4g} vs {v['target']:.4g} -> "
            + ("met" if v["met"] else "MISSED")
        )
    console.print("figures: " + ", ".join(res["figures"]))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--json", action="store_true", help="print one JSON object on the last line")
    ap.add_argument("--n", type=int, default=100_000, help="random reachable poses")
    ap.add_argument("--ikpy-n", type=int, default=300, help="ikpy subset size")
    ap.add_argument("--ga-cycles", type=int, default=CHAPTER.ga_cycles)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument(
        "--quick", action="store_true", help="smoke run: 2,000 poses, 3 GA cycles, 20 ikpy poses"
    )
    args = ap.parse_args(argv)
    if args.quick:
        args.n, args.ikpy_n, args.ga_cycles = 2000, 20, 3
    err = Console(stderr=True)
    with Progress(
        TextColumn("{task.description}"), BarColumn(), TimeElapsedColumn(), console=err
    ) as progress:
        res = run(args.n, args.ikpy_n, args.seed, args.ga_cycles, progress)
    print_tables(res, Console(file=sys.stdout, width=160))
    if args.json:
        print(json.dumps(res, default=float))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
