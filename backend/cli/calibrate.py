"""``visioncell calibrate ...``: offline intrinsic and hand-eye calibration from image folders.

``--board COLSxROWS`` counts inner corners; ``--square`` takes a length with a unit
(``25mm``, ``2.5cm``, ``0.025m``); a plain number is millimetres.  What the commands share
is in :mod:`backend.cli.calibration_common`; ``auto`` (in the simulated cell) in
:mod:`backend.cli.calibration_auto`, ``export`` and ``import`` in
:mod:`backend.cli.calibration_io`.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from pathlib import Path
from typing import Annotated, Any

import numpy as np
import typer
from rich.table import Table

from backend.cli.calibration_common import (
    JsonOpt,
    SaveOpt,
    _fail,
    _finish,
    _progress,
    err,
    out,
)

__all__ = ["calibrate_app"]

calibrate_app = typer.Typer(
    help="Calibration: intrinsics (chapter 3.1) and the eye-in-hand transform T_ee_cam "
    "(chapter 3.3) from a folder of images, the automatic calibration of a running cell, "
    "and calibrations exported from or imported into a cell.",
    no_args_is_help=True,
)

ImagesOpt = Annotated[Path, typer.Option("--images", help="Folder of board images")]
BoardOpt = Annotated[
    str, typer.Option("--board", help="Inner corners per row x per column, e.g. 9x6")
]
SquareOpt = Annotated[
    str, typer.Option("--square", help="Square side with a unit: 25mm, 2.5cm, 0.025m (plain = mm)")
]
RadialOpt = Annotated[
    bool,
    typer.Option("--radial-only", help="Hold p1 = p2 = 0 (the chapter's advice for stability)"),
]
K3Opt = Annotated[bool, typer.Option("--k3", help="Also estimate the third radial term k3")]
FixAspectOpt = Annotated[bool, typer.Option("--fix-aspect", help="One focal length (fx = fy)")]
NoRejectOpt = Annotated[bool, typer.Option("--keep-outliers", help="Do not drop outlier images")]
ReportOpt = Annotated[
    Path | None, typer.Option("--report", help="Write a PNG report (residuals, coverage, ...)")
]


def _board(board: str, square: str) -> Any:
    from vision.calibration import Chessboard, parse_board_size, parse_length_m

    try:
        cols, rows = parse_board_size(board)
        return Chessboard(cols, rows, parse_length_m(square, name="square"))
    except ValueError as exc:
        raise _fail(str(exc)) from None


def _images(folder: Path) -> list[Path]:
    from vision.calibration.io import list_images

    try:
        files = list_images(folder)
    except ValueError as exc:
        raise _fail(str(exc)) from None
    if not files:
        raise _fail(f"images: the folder {str(folder)!r} holds no PNG/JPEG/BMP/TIFF images")
    return files


def _detect(
    files: list[Path], board: Any, update: Callable[[float, str], None], share: float
) -> list[Any]:
    from vision.calibration import detect_pattern
    from vision.calibration.io import read_gray

    dets = []
    for k, f in enumerate(files):
        dets.append(detect_pattern(read_gray(f), board))
        update(share * (k + 1) / len(files), f"detecting {f.name}")
    return dets


def _fmt(v: float, nd: int = 3) -> str:
    return f"{v:.{nd}f}" if math.isfinite(v) else "-"


def _print_intrinsics(r: Any) -> None:
    t = Table(
        title=f"Intrinsics ({r.options.describe()}): RMS {r.rms_px:.3f} px, "
        f"{len(r.views)} images used, {len(r.rejected)} rejected"
    )
    t.add_column("image")
    t.add_column("RMS px", justify="right")
    t.add_column("max px", justify="right")
    t.add_column("corners", justify="right")
    for v in r.views:
        t.add_row(v.name, _fmt(v.rms_px), _fmt(v.max_px), str(v.n_points))
    out.print(t)
    if r.rejected:
        rt = Table(title="Rejected images")
        rt.add_column("image")
        rt.add_column("reason")
        for x in r.rejected:
            rt.add_row(x.name, x.reason)
        out.print(rt)
    pt = Table(title="Parameters (± one standard deviation)")
    pt.add_column("parameter")
    pt.add_column("value", justify="right")
    pt.add_column("std", justify="right")
    K = r.K
    for name, val, sd in zip(
        ("fx", "fy", "cx", "cy"), (K[0, 0], K[1, 1], K[0, 2], K[1, 2]), r.std_K, strict=True
    ):
        pt.add_row(f"{name} (px)", _fmt(val), _fmt(sd))
    for name, val, sd in zip(("k1", "k2", "p1", "p2", "k3"), r.dist, r.std_dist, strict=True):
        pt.add_row(name, f"{val:.6f}", f"{sd:.6f}")
    out.print(pt)
    out.print(
        f"coverage: corners in {r.coverage.fraction:.0%} of the image grid, "
        f"{r.coverage.corner_cells}/4 image corners; board orientations differ by up to "
        f"{r.diversity.max_angle_deg:.1f} deg"
    )


def _print_hand_eye(h: Any) -> None:
    from scipy.spatial.transform import Rotation

    ct = Table(title="Hand-eye solvers (board pose predicted per sample, spread about the mean)")
    ct.add_column("method")
    ct.add_column("reproj. RMS px", justify="right")
    ct.add_column("spread mm", justify="right")
    ct.add_column("spread deg", justify="right")
    ct.add_column("t_ee_cam (mm)", justify="right")
    for c in h.candidates:
        t = np.asarray(c.T_ee_cam)[:3, 3] * 1e3
        mark = " (best)" if c.method == h.method else ""
        ct.add_row(
            c.method + mark,
            _fmt(c.rms_px),
            _fmt(c.spread_mm),
            _fmt(c.spread_deg, 4),
            ", ".join(f"{v:.2f}" for v in t),
        )
    out.print(ct)
    pt = Table(title=f"Per pose ({h.method}{' + reprojection refinement' if h.refined else ''})")
    pt.add_column("pose")
    pt.add_column("board mm", justify="right")
    pt.add_column("board deg", justify="right")
    pt.add_column("reproj. RMS px", justify="right")
    for p in h.poses:
        pt.add_row(p.name, _fmt(p.translation_mm), _fmt(p.rotation_deg, 4), _fmt(p.rms_px))
    out.print(pt)
    if h.rejected:
        rt = Table(title="Rejected samples")
        rt.add_column("sample")
        rt.add_column("reason")
        for x in h.rejected:
            rt.add_row(x.name, x.reason)
        out.print(rt)
    T = h.T_ee_cam
    euler = Rotation.from_matrix(T[:3, :3]).as_euler("xyz", degrees=True)
    (mm_rms, mm_max), (deg_rms, deg_max) = h.consistency_mm, h.consistency_deg
    out.print(
        f"T_ee_cam: t = ({', '.join(f'{v:.2f}' for v in T[:3, 3] * 1e3)}) mm, "
        f"rotation xyz = ({', '.join(f'{v:.3f}' for v in euler)}) deg"
    )
    out.print(
        f"consistency of the board pose in the base frame: RMS {mm_rms:.3f} mm (max {mm_max:.3f}), "
        f"RMS {deg_rms:.4f} deg (max {deg_max:.4f}); reprojection RMS {h.rms_px:.3f} px"
    )
    d = h.diversity
    out.print(
        f"motion: {d.n_poses} poses, largest rotation {d.max_angle_deg:.1f} deg, "
        f"rotation axes spread {d.axis_spread_deg:.1f} deg"
    )
    for w in h.warnings:
        out.print(f"[yellow]warning:[/yellow] {w}")


@calibrate_app.command("intrinsics")
def calibrate_intrinsics_cmd(
    images: ImagesOpt,
    board: BoardOpt,
    square: SquareOpt,
    radial_only: RadialOpt = False,
    k3: K3Opt = False,
    fix_aspect: FixAspectOpt = False,
    keep_outliers: NoRejectOpt = False,
    as_json: JsonOpt = False,
    save: SaveOpt = None,
    report: ReportOpt = None,
) -> None:
    """Solve K and the lens distortion (eqs. 1-5) from chessboard images and print a report."""
    from vision.calibration import IntrinsicsOptions, calibrate_intrinsics_from_detections
    from vision.errors import CalibrationError

    b = _board(board, square)
    files = _images(images)
    opts = IntrinsicsOptions(
        radial_only=radial_only,
        k3=k3,
        fix_aspect_ratio=fix_aspect,
        reject_outliers=not keep_outliers,
    )
    with _progress(True) as update:
        dets = _detect(files, b, update, 0.9)
        try:
            r = calibrate_intrinsics_from_detections(
                dets, b, names=[f.name for f in files], options=opts
            )
        except CalibrationError as exc:
            raise _fail(exc.detail) from None
        update(1.0, "solved")
    if not as_json:
        out.print(f"[bold]{b.describe()}[/bold], {len(files)} images in {images}")
        _print_intrinsics(r)
    if report is not None:
        from vision.calibration.report import summary_png

        report.write_bytes(summary_png(r))
        err.print(f"report written to {report}")
    _finish(r.as_dict(), as_json, save)


@calibrate_app.command("hand-eye")
def calibrate_hand_eye_cmd(
    images: ImagesOpt,
    poses: Annotated[
        Path,
        typer.Option(
            "--poses", help="Text file: one row-major 4x4 T_base_ee per line, line i = image i"
        ),
    ],
    board: BoardOpt,
    square: SquareOpt,
    intrinsics: Annotated[
        Path | None,
        typer.Option(
            "--intrinsics",
            help="Intrinsics file (JSON from `calibrate intrinsics --save`, or OpenCV YAML); "
            "default: solve them from the same images",
        ),
    ] = None,
    poses_unit: Annotated[str, typer.Option("--poses-unit", help="m or mm")] = "m",
    method: Annotated[
        str,
        typer.Option(
            "--method",
            help="Solvers to try: all, or a comma list of tsai, park, horaud, andreff, daniilidis, shah, li",
        ),
    ] = "all",
    no_refine: Annotated[
        bool, typer.Option("--no-refine", help="Keep the best closed-form solution")
    ] = False,
    loss: Annotated[
        str, typer.Option("--loss", help="Refinement loss: linear, huber, soft_l1, cauchy")
    ] = "linear",
    radial_only: RadialOpt = False,
    k3: K3Opt = False,
    as_json: JsonOpt = False,
    save: SaveOpt = None,
    report: ReportOpt = None,
) -> None:
    """Solve T_ee_cam (eq. 12) from images of a fixed board and the robot's poses."""
    from vision.calibration import (
        ALL_METHODS,
        HandEyeOptions,
        IntrinsicsOptions,
        calibrate_hand_eye,
        calibrate_intrinsics_from_detections,
    )
    from vision.calibration.io import read_intrinsics, read_poses
    from vision.errors import CalibrationError

    b = _board(board, square)
    files = _images(images)
    if poses_unit not in ("m", "mm"):
        raise _fail(f"poses-unit must be m or mm, got {poses_unit!r}")
    methods = ALL_METHODS if method == "all" else tuple(m.strip() for m in method.split(","))
    try:
        P = read_poses(poses, unit_m=1e-3 if poses_unit == "mm" else 1.0)
        he_opts = HandEyeOptions(methods=methods, refine=not no_refine, loss=loss)
        camera = read_intrinsics(intrinsics) if intrinsics is not None else None
    except ValueError as exc:
        raise _fail(str(exc)) from None
    if P.shape[0] != len(files):
        raise _fail(
            f"poses: {poses.name} has {P.shape[0]} poses but {images} holds {len(files)} images; "
            "line i of the poses file must belong to image i"
        )
    names = [f.name for f in files]
    with _progress(True) as update:
        dets = _detect(files, b, update, 0.8)
        try:
            intr = None
            if camera is None:
                intr = calibrate_intrinsics_from_detections(
                    dets, b, names=names, options=IntrinsicsOptions(radial_only=radial_only, k3=k3)
                )
                camera = intr.camera
            h = calibrate_hand_eye(
                dets,
                P,
                b,
                camera,
                names=names,
                options=he_opts,
                progress=lambda f, m: update(0.8 + 0.2 * f, m),
            )
        except CalibrationError as exc:
            raise _fail(exc.detail) from None
        except ValueError as exc:
            raise _fail(str(exc)) from None
    if not as_json:
        out.print(f"[bold]{b.describe()}[/bold], {len(files)} images in {images}, poses {poses}")
        if intr is not None:
            _print_intrinsics(intr)
        else:
            out.print(f"intrinsics from {intrinsics}: fx {camera.fx:.2f}, fy {camera.fy:.2f} px")
        _print_hand_eye(h)
    if report is not None:
        from vision.calibration.report import residuals_png, summary_png

        report.write_bytes(summary_png(intr, h) if intr is not None else residuals_png(h))
        err.print(f"report written to {report}")
    result = {"hand_eye": h.as_dict(), "intrinsics": intr.as_dict() if intr is not None else None}
    _finish(result, as_json, save)
