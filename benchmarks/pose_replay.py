"""Record the pose fits of an inspection run, then fit them again offline (issue 14).

    python -m benchmarks.pose_replay record DIR -- [benchmarks.inspection arguments]
    python -m benchmarks.pose_replay replay DIR [--parts a,b] [--plot FILE.png] [--json]
    python -m benchmarks.pose_replay          # both: a short run recorded in a temporary
                                              # folder (DEFAULT_RUN), then replayed

A campaign of ``benchmarks.inspection`` takes minutes per part, most of it rendering and
recognition; the pose fit (:func:`vision.pose.estimate_pose_views`) takes tens of
milliseconds.  ``record`` runs ``benchmarks.inspection`` with the given arguments and saves
every call of that fit with what it was given (the verified trained top views: homography,
inlier correspondences, camera poses, regions, triangulated heights; the current camera
pose, heights and region; every taught top view's region), the answer it gave, and the
simulator's truth of the object at exposure (for evaluation only, as in the benchmark), one
``.npz`` per call (no pickles).  ``replay`` fits each record again with the code as it now
stands and prints, per part, the position and yaw errors of the recorded answers against
those of the fit now, on the same inputs: a change to the fit is measured on a few hundred
inspections in seconds.  ``--plot`` draws the yaw errors' distribution of both.

The yaw is scored for parts without rotational symmetry only (the benchmark's rule: not
the wheels).  At constant belt speed the truth is taken when the top view's frame is found
(``benchmarks.inspection`` moves it back by the belt's travel since the exposure), so the
recorded errors there carry that timing too.
"""

from __future__ import annotations

import argparse
import contextvars
import json
import sys
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray
from rich.console import Console
from rich.progress import Progress
from rich.table import Table

#: Most records one ``record`` run writes (each is about 0.1-0.5 MB).
MAX_RECORDS = 5000
#: Most records one ``replay`` reads.
MAX_REPLAY = 20000
#: The run recorded without arguments (``make bench``): the twelve models taught, then a
#: few objects in index mode.
DEFAULT_RUN = ["--objects", "6", "--policies", "two-views", "--objects-constant", "0",
               "--objects-light", "0", "--objects-sort", "0"]  # fmt: skip

_truth: contextvars.ContextVar[dict[str, Any] | None] = contextvars.ContextVar(
    "pose_replay_truth", default=None
)


def _pack(mask: NDArray[np.bool_] | None, key: str, out: dict[str, NDArray[Any]]) -> None:
    if mask is not None:
        m = np.asarray(mask, dtype=bool)
        out[key] = np.packbits(m, axis=None)
        out[key + "_shape"] = np.asarray(m.shape, dtype=np.int64)


def _unpack(z: Any, key: str) -> NDArray[np.bool_] | None:
    if key not in z:
        return None
    shape = tuple(int(v) for v in z[key + "_shape"])
    n = int(np.prod(shape))
    return np.unpackbits(z[key], count=n).astype(bool).reshape(shape)


def save_record(
    path: Path,
    matches: list[Any],
    kw: dict[str, Any],
    silhouettes: list[Any],
    truth: dict[str, Any] | None,
    result: Any,
) -> None:
    """One call of the fit as ``.npz`` (arrays and one JSON string only)."""
    cam = kw["camera"]
    out: dict[str, NDArray[Any]] = {
        "K": np.asarray(cam.K, np.float64),
        "dist": np.asarray(cam.dist, np.float64),
        "cam_size": np.asarray([cam.width, cam.height], np.int64),
        "T_now": np.asarray(kw["T_base_cam_now"], np.float64),
        "z": np.asarray([kw["z_plane_m"], kw["z_floor_m"]], np.float64),
    }
    _pack(kw.get("query_mask"), "query_mask", out)
    for i, m in enumerate(matches):
        p = f"m{i}_"
        out[p + "H"] = np.asarray(m.H, np.float64)
        out[p + "inlier_xy"] = np.asarray(m.inlier_xy, np.float64).reshape(-1, 4)
        out[p + "T_cam"] = np.asarray(m.T_base_cam_view, np.float64)
        out[p + "T_obj"] = np.asarray(m.T_base_obj_taught, np.float64)
        out[p + "view_shape"] = np.asarray(m.view_shape, np.int64)
        _pack(m.view_mask, p + "mask", out)
        if m.heights is not None:
            out[p + "heights"] = np.asarray(m.heights, np.float64)
    for i, s in enumerate(silhouettes):
        out[f"s{i}_T_cam"] = np.asarray(s.T_base_cam_view, np.float64)
        out[f"s{i}_T_obj"] = np.asarray(s.T_base_obj_taught, np.float64)
        _pack(s.mask(), f"s{i}_mask", out)
    if result is not None:
        out["result_T"] = np.asarray(result.T_base_obj, np.float64)
    meta = {
        "matches": len(matches),
        "silhouettes": len(silhouettes),
        "truth_name": None if truth is None else truth["name"],
        "truth_T": None if truth is None else truth["T_base_obj"],
        "failed": result is None,
    }
    out["meta"] = np.asarray(json.dumps(meta))
    np.savez_compressed(path, **out)


def load_record(path: Path) -> dict[str, Any]:
    """A record as the fit's arguments: ``matches``, ``kw``, ``silhouettes``, ``truth``
    (name and ``T``, or None) and the recorded answer's ``result_T`` (None when it failed)."""
    from vision.camera import PinholeCamera
    from vision.pose import SilhouetteView, ViewMatch, fixed_mask

    with np.load(path, allow_pickle=False) as z:
        meta = json.loads(str(z["meta"]))
        w, h = (int(v) for v in z["cam_size"])
        cam = PinholeCamera(z["K"], z["dist"], width=w, height=h)
        matches = []
        for i in range(int(meta["matches"])):
            p = f"m{i}_"
            shape = tuple(int(v) for v in z[p + "view_shape"])
            heights = z.get(p + "heights")
            matches.append(ViewMatch(z[p + "H"], z[p + "inlier_xy"], z[p + "T_cam"],
                                     z[p + "T_obj"], _unpack(z, p + "mask"), shape, heights))  # fmt: skip
        sil = [
            SilhouetteView(z[f"s{i}_T_cam"], z[f"s{i}_T_obj"], fixed_mask(_unpack(z, f"s{i}_mask")))
            for i in range(int(meta["silhouettes"]))
        ]
        kw = {
            "camera": cam,
            "T_base_cam_now": z["T_now"],
            "z_plane_m": float(z["z"][0]),
            "z_floor_m": float(z["z"][1]),
            "query_mask": _unpack(z, "query_mask"),
        }
        result_T = None if "result_T" not in z else np.array(z["result_T"])
    truth = None
    if meta["truth_name"] is not None:
        truth = {"name": meta["truth_name"], "T": np.asarray(meta["truth_T"], np.float64)}
    return {"matches": matches, "kw": kw, "silhouettes": sil, "truth": truth,
            "result_T": result_T}  # fmt: skip


def record(out_dir: Path, argv: list[str]) -> None:
    """Run ``benchmarks.inspection`` with ``argv``, saving every pose fit in ``out_dir``."""
    from backend.inspection import pose as pose_stage
    from backend.inspection import recognise as recognise_stage
    from benchmarks import inspection

    out_dir.mkdir(parents=True, exist_ok=True)
    fit, truth_near = pose_stage.estimate_pose_views, recognise_stage.truth_near
    count = [len(list(out_dir.glob("*.npz")))]

    def truth_wrapper(*a: Any, **k: Any) -> Any:
        t = truth_near(*a, **k)
        _truth.set(t)
        return t

    def fit_wrapper(matches: list[Any], **kw: Any) -> Any:
        result, error = None, None
        try:
            result = fit(matches, **kw)
        except Exception as exc:  # recorded, then raised as before
            error = exc
        if count[0] < MAX_RECORDS:
            sil = kw.get("silhouettes") or []
            save_record(out_dir / f"{count[0]:05d}.npz", matches,
                        {k: v for k, v in kw.items() if k != "silhouettes"}, sil,
                        _truth.get(), result)  # fmt: skip
            count[0] += 1
        if error is not None:
            raise error
        return result

    pose_stage.estimate_pose_views, recognise_stage.truth_near = fit_wrapper, truth_wrapper
    try:
        inspection.main(argv)
    finally:
        pose_stage.estimate_pose_views, recognise_stage.truth_near = fit, truth_near
    Console(stderr=True).print(f"[pose_replay] {count[0]} records in {out_dir}")


def replay(
    in_dir: Path, parts: tuple[str, ...] = (), limit: int = MAX_REPLAY
) -> list[dict[str, Any]]:
    """Fit every record of ``in_dir`` again; one row per record with a truth."""
    from benchmarks.inspection import SYMMETRIC, pose_errors
    from robot.sim.catalogue import CATALOGUE
    from vision.pose import PoseFailed, estimate_pose_views

    files = sorted(in_dir.glob("*.npz"))[:limit]
    rows: list[dict[str, Any]] = []
    with Progress(console=Console(stderr=True), transient=True) as bar:
        task = bar.add_task("fitting again", total=len(files))
        for f in files:
            bar.advance(task)
            rec = load_record(f)
            t = rec["truth"]
            if t is None or (parts and t["name"] not in parts):
                continue
            try:
                T_now = estimate_pose_views(rec["matches"], silhouettes=rec["silhouettes"],
                                            **rec["kw"]).T_base_obj  # fmt: skip
            except PoseFailed:
                T_now = None
            symmetric = t["name"] in CATALOGUE and CATALOGUE[t["name"]].kind in SYMMETRIC
            row: dict[str, Any] = {"file": f.name, "name": t["name"]}
            for key, T in (("recorded", rec["result_T"]), ("now", T_now)):
                err = None if T is None else pose_errors(T, t["T"], symmetric)
                row[key] = None if err is None else {"pos_mm": err[0], "yaw_deg": err[1]}
            rows.append(row)
    return rows


def summarise(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Per part and over all: errors of the recorded answers and of the fit now."""
    out = []
    for name in [*sorted({r["name"] for r in rows}), "all"]:
        sel = [r for r in rows if name in ("all", r["name"])]
        line: dict[str, Any] = {"part": name, "records": len(sel)}
        for key in ("recorded", "now"):
            got = [r[key] for r in sel if r[key] is not None]
            pos = [g["pos_mm"] for g in got]
            yaw = [g["yaw_deg"] for g in got if g["yaw_deg"] is not None]
            line[key] = {
                "failed": len(sel) - len(got),
                "pos_mm": _q(pos),
                "pos_over_2mm": sum(p > 2.0 for p in pos),
                "yaw_deg": _q(yaw),
                "yaw_over_1deg": sum(y > 1.0 for y in yaw),
                "yaw_n": len(yaw),
            }
        out.append(line)
    return out


def _q(v: list[float]) -> list[float] | None:
    if not v:
        return None
    return [round(float(x), 3) for x in np.percentile(v, [50, 95, 100])]


def _plot(rows: list[dict[str, Any]], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6, 4))
    for key, style in (("recorded", "--"), ("now", "-")):
        y = np.sort([r[key]["yaw_deg"] for r in rows
                     if r[key] is not None and r[key]["yaw_deg"] is not None])  # fmt: skip
        if len(y):
            ax.plot(y, np.arange(1, len(y) + 1) / len(y), style, label=f"{key} ({len(y)})")
    ax.axvline(1.0, color="grey", lw=0.8)
    ax.set_xlabel("yaw error, degrees")
    ax.set_ylabel("share of inspections at or below")
    ax.set_title("Pose fit: recorded answers and the fit now, same inputs")
    ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _fmt(s: dict[str, Any]) -> tuple[str, str]:
    def q(v: list[float] | None) -> str:
        return "-" if v is None else " / ".join(f"{x:.2f}" for x in v)

    pos = f"{q(s['pos_mm'])} ({s['pos_over_2mm']} > 2)"
    yaw = "-" if s["yaw_deg"] is None else f"{q(s['yaw_deg'])} ({s['yaw_over_1deg']} > 1)"
    return pos, yaw


def main(argv: list[str] | None = None) -> None:
    argv = list(sys.argv[1:] if argv is None else argv)
    if not argv:
        import tempfile

        with tempfile.TemporaryDirectory(prefix="pose-replay-") as tmp:
            record(Path(tmp), DEFAULT_RUN)
            main(["replay", tmp])
        return
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    rec = sub.add_parser("record", help="run benchmarks.inspection and record its pose fits")
    rec.add_argument("dir", type=Path)
    rep = sub.add_parser("replay", help="fit the records again with the code as it stands")
    rep.add_argument("dir", type=Path)
    rep.add_argument("--parts", default="", help="comma-separated catalogue names")
    rep.add_argument("--limit", type=int, default=MAX_REPLAY)
    rep.add_argument("--plot", type=Path, default=None, help="PNG of the yaw errors")
    rep.add_argument("--json", action="store_true")
    rest: list[str] = []
    if "--" in argv:
        i = argv.index("--")
        argv, rest = argv[:i], argv[i + 1 :]
    args = ap.parse_args(argv)
    if args.cmd == "record":
        record(args.dir, rest)
        return
    if rest:
        ap.error("replay takes no benchmarks.inspection arguments")
    if not args.dir.is_dir():
        ap.error(f"no such directory of records: {args.dir}")
    if not 1 <= args.limit <= MAX_REPLAY:
        ap.error(f"--limit must be in 1..{MAX_REPLAY}, got {args.limit}")
    parts = tuple(p.strip() for p in args.parts.split(",") if p.strip())
    from robot.sim.catalogue import CATALOGUE

    unknown = [p for p in parts if p not in CATALOGUE]
    if unknown:
        ap.error(f"--parts: not in the catalogue: {unknown}; valid: {', '.join(CATALOGUE)}")
    rows = replay(args.dir, parts, args.limit)
    summary = summarise(rows)
    if args.plot is not None:
        _plot(rows, args.plot)
    if args.json:
        print(json.dumps({"summary": summary, "rows": rows}))
        return
    table = Table(title=f"Pose fits of {args.dir}: recorded against now (p50 / p95 / max)")
    for col in ("part", "n", "pos mm, recorded", "pos mm, now", "yaw deg, recorded",
                "yaw deg, now"):  # fmt: skip
        table.add_column(col)
    for s in summary:
        (pr, yr), (pn, yn) = _fmt(s["recorded"]), _fmt(s["now"])
        table.add_row(s["part"], str(s["records"]), pr, pn, yr, yn)
    Console().print(table)


if __name__ == "__main__":
    main()
