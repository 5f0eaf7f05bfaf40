"""benchmarks.pose_replay: a recorded pose fit loads back to the same fit, and replay
scores it against the truth (the recording run itself is benchmarks.inspection's)."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from benchmarks import pose_replay
from tests.vision.test_bug_pose_parallax import SURFACE, _scene
from vision.pose import SilhouetteView, ViewMatch, estimate_pose_views, fixed_mask


def _call(yaw_deg: float, seed: int):
    H, pairs, kw, truth = _scene(math.radians(yaw_deg), 0.002, -0.001, 2.094, seed=seed)
    heights = np.full(len(pairs), np.nan)
    heights[:5] = 0.5
    m = ViewMatch(H, pairs, kw["T_base_cam_view"], kw["T_base_obj_taught"], kw["view_mask"],
                  kw["view_shape"], heights)  # fmt: skip
    fit_kw = dict(camera=kw["camera"], T_base_cam_now=kw["T_base_cam_now"],
                  z_plane_m=kw["z_plane_m"], z_floor_m=SURFACE, query_mask=kw["view_mask"])  # fmt: skip
    sil = [
        SilhouetteView(kw["T_base_cam_view"], kw["T_base_obj_taught"], fixed_mask(kw["view_mask"]))
    ]
    return [m], fit_kw, sil, truth


def test_a_record_loads_back_to_the_same_fit(tmp_path):
    matches, kw, sil, truth = _call(30, 1)
    pose = estimate_pose_views(matches, silhouettes=sil, **kw)
    path = tmp_path / "00000.npz"
    pose_replay.save_record(path, matches, kw, sil,
                            {"name": "wheel-5spoke", "T_base_obj": truth.tolist()}, pose)  # fmt: skip
    with np.load(path, allow_pickle=False) as z:  # arrays only
        assert "meta" in z
    rec = pose_replay.load_record(path)
    again = estimate_pose_views(rec["matches"], silhouettes=rec["silhouettes"], **rec["kw"])
    np.testing.assert_allclose(again.T_base_obj, pose.T_base_obj, atol=1e-9)
    np.testing.assert_array_equal(rec["matches"][0].view_mask, matches[0].view_mask)
    np.testing.assert_array_equal(rec["matches"][0].heights, matches[0].heights)
    np.testing.assert_allclose(rec["result_T"], pose.T_base_obj)
    assert rec["truth"]["name"] == "wheel-5spoke"


def test_replay_scores_recorded_and_current_answers(tmp_path, capsys):
    for i, (yaw, name) in enumerate([(30, "pipe-flange"), (-120, "pipe-flange"),
                                     (75, "wheel-5spoke")]):  # fmt: skip
        matches, kw, sil, truth = _call(yaw, i)
        pose = estimate_pose_views(matches, silhouettes=sil, **kw)
        recorded = pose
        if i == 1:  # as if the recorded fit had been 3 mm and 2 degrees off
            T = pose.T_base_obj.copy()
            c, s = math.cos(math.radians(2)), math.sin(math.radians(2))
            T[:2, :2] = np.array([[c, -s], [s, c]]) @ T[:2, :2]
            T[0, 3] += 0.003
            recorded = type(pose)(T, 0.0, 0.0, 0)
        pose_replay.save_record(tmp_path / f"{i:05d}.npz", matches, kw, sil,
                                {"name": name, "T_base_obj": truth.tolist()}, recorded)  # fmt: skip
    pose_replay.save_record(tmp_path / "00003.npz", matches, kw, sil, None, pose)  # no truth
    rows = pose_replay.replay(tmp_path)
    assert len(rows) == 3
    wheel = next(r for r in rows if r["name"] == "wheel-5spoke")
    assert wheel["now"]["yaw_deg"] is None  # a wheel's yaw is not scored
    summary = {s["part"]: s for s in pose_replay.summarise(rows)}
    flange = summary["pipe-flange"]
    assert flange["recorded"]["pos_over_2mm"] == 1 and flange["recorded"]["yaw_over_1deg"] == 1
    assert flange["now"]["pos_over_2mm"] == 0 and flange["now"]["yaw_over_1deg"] == 0
    assert summary["all"]["records"] == 3
    pose_replay.main(["replay", str(tmp_path), "--parts", "pipe-flange", "--json",
                      "--plot", str(tmp_path / "yaw.png")])  # fmt: skip
    out = json.loads(capsys.readouterr().out)
    assert [s["part"] for s in out["summary"]] == ["pipe-flange", "all"]
    assert (tmp_path / "yaw.png").stat().st_size > 1000


@pytest.mark.parametrize(
    "argv,message",
    [
        (["replay", "/nonexistent/records"], "no such directory"),
        (["replay", ".", "--limit", "0"], "--limit must be in"),
        (["replay", ".", "--", "--objects", "3"], "takes no benchmarks.inspection arguments"),
        (["replay", ".", "--parts", "pipe-flange,flux-capacitor"], "'flux-capacitor'"),
    ],
)
def test_bad_arguments_are_named(argv, message, capsys):
    with pytest.raises(SystemExit) as exc:
        pose_replay.main(argv)
    assert exc.value.code == 2
    assert message in capsys.readouterr().err
