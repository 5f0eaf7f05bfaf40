"""Calibration figures on the real data sets, next to plain OpenCV measured in the same run.

- ``calibration/opencv-left`` (13 photos, 9x6 board): RMS and focal lengths of
  ``vision.calibration`` against OpenCV's classic recipe (``findChessboardCorners`` +
  ``cornerSubPix`` + ``calibrateCamera``) and OpenCV's reference fx = fy = 535.9.
- ``calibration/handeye-kuka2`` (28 eye-in-hand photos, 24x17 board, 15 mm): the board pose
  in the base frame predicted from every sample, spread in mm and degrees, for each hand-eye
  solver and after the reprojection refinement, against plain OpenCV (classic detector,
  ``calibrateCamera``, ``calibrateHandEye`` with its default Tsai method).

- The simulated cell (:mod:`benchmarks.calibration_sim`): automatic calibration runs judged
  against the simulator's ground truth, next to the nominal model they start from.

Run ``python -m benchmarks.calibration [--json] [--data-dir DIR] [--skip-kuka] [--skip-sim]``; a report
picture goes to ``benchmarks/out/calibration-report.png``.
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
from rich.progress import Progress
from rich.table import Table

from vision.calibration import (
    Chessboard,
    HandEyeOptions,
    calibrate_hand_eye,
    calibrate_intrinsics_from_detections,
    detect_pattern,
)
from vision.calibration.io import list_images, read_gray, read_intrinsics, read_poses
from vision.calibration.report import summary_png

REPO = Path(__file__).resolve().parents[1]
OUT = REPO / "benchmarks" / "out"
REFERENCE_F = 535.9
LEFT_BOARD = Chessboard(9, 6, 0.025)
KUKA_BOARD = Chessboard(24, 17, 0.015)

out = Console()
err = Console(stderr=True)


def _classic_corners(gray: np.ndarray, size: tuple[int, int]) -> np.ndarray | None:
    """OpenCV's tutorial recipe: findChessboardCorners, then cornerSubPix in an 11x11 window."""
    ok, c = cv2.findChessboardCorners(gray, size, None)
    if not ok:
        return None
    return cv2.cornerSubPix(
        gray, c, (11, 11), (-1, -1), (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 30, 0.001)
    )


def _spread(T: np.ndarray) -> dict[str, float]:
    """RMS and max distance / angle of poses (N, 4, 4) from their mean, mm and degrees."""
    from scipy.spatial.transform import Rotation

    t = T[:, :3, 3]
    d = np.linalg.norm(t - t.mean(axis=0), axis=1) * 1e3
    R = Rotation.from_matrix(T[:, :3, :3])
    a = np.degrees((R.mean().inv() * R).magnitude())
    return {
        "rms_mm": float(np.sqrt(np.mean(d**2))),
        "max_mm": float(d.max()),
        "rms_deg": float(np.sqrt(np.mean(a**2))),
        "max_deg": float(a.max()),
    }


def bench_opencv_left(folder: Path, progress: Any) -> dict[str, Any]:
    files = list_images(folder)
    grays = [read_gray(f) for f in files]
    task = progress.add_task("opencv-left", total=2 * len(files))
    t0 = time.perf_counter()
    dets = []
    for g in grays:
        dets.append(detect_pattern(g, LEFT_BOARD))
        progress.advance(task)
    ours = calibrate_intrinsics_from_detections(dets, LEFT_BOARD, names=[f.name for f in files])
    t_ours = time.perf_counter() - t0

    t0 = time.perf_counter()
    obj, img = [], []
    for g in grays:
        c = _classic_corners(g, LEFT_BOARD.pattern_size)
        if c is not None:
            obj.append(LEFT_BOARD.object_points().astype(np.float32))
            img.append(c)
        progress.advance(task)
    rms_b, K_b, *_ = cv2.calibrateCamera(obj, img, (640, 480), None, None)
    t_base = time.perf_counter() - t0
    ref = read_intrinsics(folder / "left_intrinsics.yml")

    def row(name: str, rms: float, K: np.ndarray, n: int, secs: float) -> dict[str, Any]:
        return {
            "method": name,
            "rms_px": float(rms),
            "fx": float(K[0, 0]),
            "fy": float(K[1, 1]),
            "fx_err_pct": float(100 * (K[0, 0] / REFERENCE_F - 1)),
            "fy_err_pct": float(100 * (K[1, 1] / REFERENCE_F - 1)),
            "views": n,
            "time_s": secs,
        }

    return {
        "rows": [
            row(
                "vision.calibration (sector-based detector, k1 k2 p1 p2)",
                ours.rms_px,
                ours.K,
                len(ours.views),
                t_ours,
            ),
            row(
                "baseline: OpenCV classic detector + cornerSubPix, 5 coefficients",
                rms_b,
                K_b,
                len(img),
                t_base,
            ),
            row("OpenCV reference file (left_intrinsics.yml)", 0.3926, ref.K, 13, float("nan")),
        ],
        "result": ours,
    }


def bench_kuka(folder: Path, progress: Any, *, cross_validate: bool = True) -> dict[str, Any]:
    files = list_images(folder)
    poses = read_poses(folder / "RobotPosesVec.txt")
    names = [f.name for f in files]
    task = progress.add_task("handeye-kuka2", total=2 * len(files))
    t0 = time.perf_counter()
    dets = []
    classic = []
    t_classic = 0.0
    for f in files:
        g = read_gray(f)
        dets.append(detect_pattern(g, KUKA_BOARD))
        progress.advance(task)
        t1 = time.perf_counter()
        classic.append(_classic_corners(g, KUKA_BOARD.pattern_size))
        t_classic += time.perf_counter() - t1
        progress.advance(task)
    t_detect = time.perf_counter() - t0 - t_classic
    intr = calibrate_intrinsics_from_detections(dets, KUKA_BOARD, names=names)
    rows = []
    t0 = time.perf_counter()
    unrefined = calibrate_hand_eye(
        dets, poses, KUKA_BOARD, intr.camera, names=names, options=HandEyeOptions(refine=False)
    )
    refined = calibrate_hand_eye(dets, poses, KUKA_BOARD, intr.camera, names=names)
    t_he = time.perf_counter() - t0
    for c in unrefined.candidates:
        rows.append(
            {
                "method": c.method,
                "rms_px": c.rms_px,
                "rms_mm": c.spread_mm,
                "rms_deg": c.spread_deg,
                "t_mm": (c.T_ee_cam[:3, 3] * 1e3).tolist(),
            }
        )
    (mm_rms, mm_max), (deg_rms, deg_max) = refined.consistency_mm, refined.consistency_deg
    best_closed = next(c for c in unrefined.candidates if c.method == unrefined.method)
    b_mm_max, b_deg_max = unrefined.consistency_mm[1], unrefined.consistency_deg[1]
    rows.append(
        {
            "method": f"{refined.method} + reprojection refinement (final)",
            "rms_px": refined.rms_px,
            "rms_mm": mm_rms,
            "rms_deg": deg_rms,
            "max_mm": mm_max,
            "max_deg": deg_max,
            "t_mm": (refined.T_ee_cam[:3, 3] * 1e3).tolist(),
        }
    )
    rows[[r["method"] for r in rows].index(best_closed.method)].update(
        {"max_mm": b_mm_max, "max_deg": b_deg_max}
    )

    # Baseline: plain OpenCV, corner order as the classic detector returns it.
    ok = [i for i, c in enumerate(classic) if c is not None]
    obj = [KUKA_BOARD.object_points().astype(np.float32)] * len(ok)
    rms_b, _, _, rv, tv = cv2.calibrateCamera(
        obj, [classic[i] for i in ok], (1920, 1200), None, None
    )
    Rc = [cv2.Rodrigues(r)[0] for r in rv]
    R, t = cv2.calibrateHandEye(
        [poses[i][:3, :3] for i in ok], [poses[i][:3, 3] for i in ok], Rc, list(tv)
    )
    X = np.eye(4)
    X[:3, :3], X[:3, 3] = R, t.ravel()
    preds = []
    for k, i in enumerate(ok):
        T = np.eye(4)
        T[:3, :3], T[:3, 3] = Rc[k], tv[k].ravel()
        preds.append(poses[i] @ X @ T)
    base = _spread(np.array(preds))
    rows.append(
        {
            "method": "baseline: OpenCV classic detector + calibrateCamera + calibrateHandEye (Tsai)",
            "rms_px": float("nan"),
            "rms_mm": base["rms_mm"],
            "rms_deg": base["rms_deg"],
            "max_mm": base["max_mm"],
            "max_deg": base["max_deg"],
            "t_mm": (X[:3, 3] * 1e3).tolist(),
        }
    )
    loo = leave_one_out(dets, poses, intr.camera, progress) if cross_validate else None
    return {
        "leave_one_out": loo,
        "intrinsics": {
            "rms_px": intr.rms_px,
            "baseline_rms_px": float(rms_b),
            "fx": float(intr.K[0, 0]),
            "fy": float(intr.K[1, 1]),
            "detect_s": t_detect,
            "baseline_detect_s": t_classic,
            "hand_eye_s": t_he,
        },
        "rows": rows,
        "intrinsic_result": intr,
        "result": refined,
    }


def leave_one_out(
    dets: list[Any], poses: np.ndarray, camera: Any, progress: Any
) -> dict[str, dict[str, float]]:
    """Solve without sample i, then predict sample i: its corners in the image through
    ``T_cam_board = (T_base_ee_i T_ee_cam)^-1 T_base_board`` (pixels), and its board pose in
    the base frame ``T_base_ee_i T_ee_cam T_cam_board_i`` against the solution's (mm, deg)."""
    from vision.calibration import board_pose
    from vision.calibration.handeye import _Chain, _pose_errors

    n = len(dets)
    task = progress.add_task("leave-one-out", total=2 * n)
    Bc = np.array([board_pose(d, KUKA_BOARD, camera)[0] for d in dets])
    out: dict[str, dict[str, float]] = {}
    for label, refine in (("closed form (tsai)", False), ("tsai + refinement", True)):
        px, mm, deg = [], [], []
        for i in range(n):
            keep = [j for j in range(n) if j != i]
            r = calibrate_hand_eye(
                [dets[j] for j in keep],
                poses[keep],
                KUKA_BOARD,
                camera,
                options=HandEyeOptions(methods=("tsai",), refine=refine),
            )
            chain = _Chain(
                poses[[i]], [dets[i].object_points(KUKA_BOARD)], [dets[i].image_points], camera
            )
            px.append(chain.rms(r.T_ee_cam, r.T_base_board))
            _, d_mm, d_deg = _pose_errors((poses[i] @ r.T_ee_cam @ Bc[i])[None], r.T_base_board)
            mm.append(d_mm[0])
            deg.append(d_deg[0])
            progress.advance(task)
        rms = lambda v: float(np.sqrt(np.mean(np.square(v))))  # noqa: E731
        out[label] = {"reproj_rms_px": rms(px), "board_rms_mm": rms(mm), "board_rms_deg": rms(deg)}
    return out


def _f(v: Any, nd: int = 3) -> str:
    return "-" if v is None or (isinstance(v, float) and not np.isfinite(v)) else f"{v:.{nd}f}"


def _no_nan(v: Any) -> Any:
    """NaN (no figure) becomes null: strict JSON has no NaN."""
    if isinstance(v, float) and not np.isfinite(v):
        return None
    if isinstance(v, dict):
        return {k: _no_nan(x) for k, x in v.items()}
    if isinstance(v, list):
        return [_no_nan(x) for x in v]
    return v


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--json", action="store_true", help="print one JSON object on the last line")
    ap.add_argument("--data-dir", type=Path, default=REPO.parent / "shared" / "data")
    ap.add_argument("--skip-kuka", action="store_true", help="only the 640x480 set (fast)")
    ap.add_argument(
        "--no-loo", action="store_true", help="skip the leave-one-out check (about a minute)"
    )
    ap.add_argument(
        "--skip-sim", action="store_true", help="skip the simulated auto-calibration runs"
    )
    args = ap.parse_args(argv)
    cal = args.data_dir / "calibration"
    if not (cal / "opencv-left").is_dir():
        err.print(f"[red]error:[/red] {cal / 'opencv-left'} is absent (see the data README)")
        return 2
    with Progress(console=err, transient=True) as progress:
        left = bench_opencv_left(cal / "opencv-left", progress)
        kuka = None
        if not args.skip_kuka and (cal / "handeye-kuka2").is_dir():
            kuka = bench_kuka(cal / "handeye-kuka2", progress, cross_validate=not args.no_loo)

    t = Table(
        title="opencv-left: intrinsics (13 photos, 9x6, 25 mm; target RMS <= 0.25 px, fx, fy within 1 % of 535.9)"
    )
    for col in ("method", "RMS px", "fx", "fy", "fx err %", "fy err %", "views", "time s"):
        t.add_column(col, justify="left" if col == "method" else "right")
    for r in left["rows"]:
        t.add_row(
            r["method"],
            _f(r["rms_px"]),
            _f(r["fx"], 2),
            _f(r["fy"], 2),
            _f(r["fx_err_pct"], 2),
            _f(r["fy_err_pct"], 2),
            str(r["views"]),
            _f(r["time_s"], 2),
        )
    out.print(t)
    summary: dict[str, Any] = {"opencv_left": left["rows"]}
    OUT.mkdir(parents=True, exist_ok=True)
    if kuka is not None:
        k = kuka["intrinsics"]
        out.print(
            f"handeye-kuka2 intrinsics: RMS {k['rms_px']:.3f} px (classic detector: {k['baseline_rms_px']:.3f} px), "
            f"fx {k['fx']:.2f}, fy {k['fy']:.2f}; detection {k['detect_s']:.1f} s "
            f"(classic {k['baseline_detect_s']:.1f} s), hand-eye solve {k['hand_eye_s']:.1f} s"
        )
        t = Table(
            title="handeye-kuka2: board pose in the base frame predicted from each of the 28 samples "
            "(aim: <= 2 mm and <= 0.2 deg; ViSP's example: 5.4 mm, 0.46 deg)"
        )
        for col in (
            "method",
            "reproj. RMS px",
            "RMS mm",
            "max mm",
            "RMS deg",
            "max deg",
            "t_ee_cam mm",
        ):
            t.add_column(col, justify="left" if col == "method" else "right")
        for r in kuka["rows"]:
            t.add_row(
                r["method"],
                _f(r["rms_px"]),
                _f(r["rms_mm"]),
                _f(r.get("max_mm")),
                _f(r["rms_deg"], 4),
                _f(r.get("max_deg"), 4),
                " ".join(f"{v:.1f}" for v in r["t_mm"]),
            )
        out.print(t)
        if kuka["leave_one_out"] is not None:
            t = Table(title="handeye-kuka2 leave-one-out: solve without sample i, predict sample i")
            for col in (
                "solution",
                "image corners RMS px",
                "board pose RMS mm",
                "board pose RMS deg",
            ):
                t.add_column(col, justify="left" if col == "solution" else "right")
            for name, v in kuka["leave_one_out"].items():
                t.add_row(
                    name, _f(v["reproj_rms_px"]), _f(v["board_rms_mm"]), _f(v["board_rms_deg"], 4)
                )
            out.print(t)
        png = summary_png(kuka["intrinsic_result"], kuka["result"])
        (OUT / "calibration-report.png").write_bytes(png)
        err.print(f"report picture: {OUT / 'calibration-report.png'}")
        summary["handeye_kuka2"] = {
            "intrinsics": k,
            "hand_eye": kuka["rows"],
            "leave_one_out": kuka["leave_one_out"],
        }
    if not args.skip_sim:
        from benchmarks.calibration_sim import bench_sim, print_sim

        with Progress(console=err, transient=True) as progress:
            sim = bench_sim([0, 1, 2], ["chessboard", "charuco"], progress, n_poses=25)
        print_sim(sim)
        summary["sim_auto"] = sim
    out.print("timings are wall-clock on a shared machine; compare within one run only")
    if args.json:
        sys.stdout.write(json.dumps(_no_nan(summary)) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
